"""One exception hierarchy for flexmb. Messages say where, what was received, what was expected."""

from __future__ import annotations


class FlexmbError(Exception):
    """Base class of every error flexmb raises on purpose."""


class SceneError(FlexmbError):
    """A scene file (or dict) does not match the schema.

    Parameters
    ----------
    where : str
        ``file:key.path`` of the offending entry.
    message : str
        What was received and what was expected.
    """

    def __init__(self, where: str, message: str):
        self.where = where
        super().__init__(f"{where}: {message}")


class ConvergenceError(FlexmbError):
    """A step (or load increment) did not converge and the policy is to stop."""

    def __init__(self, message: str, result=None):
        self.result = result
        super().__init__(message)
