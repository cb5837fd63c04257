"""Retry a failed step in 2, 4, … equal pieces (the ``substep`` policy of both integrators)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..model.workspace import State
from .result import StepResult


def retry_in_pieces(failed: StepResult, piece: Callable[[int, int, np.ndarray], StepResult],
                    state: State, backup: State, lam_target: np.ndarray, levels: int,
                    what: str) -> StepResult:
    """Redo the step from ``backup`` in ``2**level`` pieces, level = 1 … ``levels``.

    ``piece(k, n, lam_k)`` advances ``state`` by the k-th of n pieces to actuator stretches
    ``lam_k`` (interpolated linearly from ``backup.lam`` to ``lam_target``). Returns the last
    piece's result (iterations summed, ``substeps`` set) or, if no split converges, ``failed``
    with ``state`` restored to ``backup``. ``what`` names the pieces in messages.
    """
    lam0 = backup.lam.copy()
    iters = failed.iterations
    for level in range(1, levels + 1):
        state.assign(backup)
        nsub = 2 ** level
        for k in range(1, nsub + 1):
            sub = piece(k, nsub, lam0 + (lam_target - lam0) * (k / nsub))
            iters += sub.iterations
            if not sub.converged:
                break
        else:
            sub.iterations = iters
            sub.substeps = nsub
            sub.message = f"split into {nsub} {what} after: {failed.message}"
            sub.guard = failed.guard or sub.guard
            return sub
    state.assign(backup)
    failed.iterations = iters
    failed.message = (f"{'no acceptable root' if failed.guard else 'no convergence'} even with "
                      f"{2 ** levels} {what}: {failed.message}")
    return failed
