"""A tiny strict reader over nested dicts: every error names ``file:key.path``, the value and
what was expected."""

from __future__ import annotations

import math
from typing import Any

from ..errors import SceneError, excerpt, name_list, near_names

_MISSING = object()
_HINTED_KEYS = 8             # unknown keys looked at for a near allowed one


def _did_you_mean(unknown: list, allowed: set[str]) -> str:
    """`` (did you mean 'dt'?)`` for the first unknown key with a close allowed one (a typo), else ''."""
    for key in sorted(unknown, key=str)[:_HINTED_KEYS]:       # bounded: a file may hold 10⁵ stray keys
        close = near_names(key, allowed)
        if close:
            return f" (did you mean {close[0]!r} for {str(key)[:40]!r}?)"
    return ""


class Node:
    """A position in the YAML tree: the value plus its dotted path for error messages."""

    def __init__(self, value: Any, path: str, source: str):
        self.value = value
        self.path = path
        self.source = source

    # -- errors -------------------------------------------------------------------------
    def where(self, key: str | int | None = None) -> str:
        p = self.path
        if key is not None:
            p = f"{p}[{key}]" if isinstance(key, int) else (f"{p}.{key}" if p else str(key))
        return f"{self.source}:{p or '<root>'}"

    def fail(self, message: str, key: str | int | None = None) -> SceneError:
        return SceneError(self.where(key), message)

    # -- structure ----------------------------------------------------------------------
    def mapping(self, allowed: set[str], required: set[str] = frozenset()) -> "Node":
        if not isinstance(self.value, dict):
            raise self.fail(f"expected a mapping, got {_typed(self.value)}")
        unknown = [k for k in self.value if k not in allowed]
        if unknown:
            raise self.fail(f"unknown key(s) {name_list(sorted(unknown, key=str))}{_did_you_mean(unknown, allowed)}; "
                            f"allowed keys: {sorted(allowed)}")
        missing = sorted(k for k in required if k not in self.value)
        if missing:
            raise self.fail(f"missing required key(s) {missing}")
        return self

    def get(self, key: str, default: Any = _MISSING) -> "Node | None":
        sub = f"{self.path}.{key}" if self.path else key
        if key in self.value:
            return Node(self.value[key], sub, self.source)
        if default is _MISSING:
            raise self.fail(f"missing required key '{key}'")
        return None if default is None else Node(default, sub, self.source)

    def has(self, key: str) -> bool:
        return isinstance(self.value, dict) and key in self.value

    def items(self):
        if not isinstance(self.value, dict):
            raise self.fail(f"expected a mapping, got {_typed(self.value)}")
        for k, v in self.value.items():
            if not isinstance(k, str) or not k:
                raise self.fail(f"names must be non-empty strings, got {excerpt(k)}")
            yield k, Node(v, f"{self.path}.{k}" if self.path else k, self.source)

    def list(self) -> list["Node"]:
        if not isinstance(self.value, list):
            raise self.fail(f"expected a list, got {_typed(self.value)}")
        return [Node(v, f"{self.path}[{i}]", self.source) for i, v in enumerate(self.value)]

    # -- scalars ------------------------------------------------------------------------
    def number(self, *, positive: bool = False, nonneg: bool = False,
               lo: float | None = None, hi: float | None = None, unit: str = "") -> float:
        v = self.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(f"expected a number{' in ' + unit if unit else ''}, got {excerpt(v)}")
        try:
            v = float(v)
        except OverflowError:            # an integer beyond any float
            raise self.fail(f"expected a finite number, got an integer of {abs(v).bit_length()} bits") from None
        if not math.isfinite(v):
            raise self.fail(f"expected a finite number, got {excerpt(v)}")
        if positive and v <= 0:
            raise self.fail(f"expected a positive number{' (' + unit + ')' if unit else ''}, got {excerpt(v)}")
        if nonneg and v < 0:
            raise self.fail(f"expected a non-negative number, got {excerpt(v)}")
        if lo is not None and v < lo:
            raise self.fail(f"expected a number ≥ {lo}, got {excerpt(v)}")
        if hi is not None and v > hi:
            raise self.fail(f"expected a number ≤ {hi}, got {excerpt(v)}")
        return v

    def integer(self, *, lo: int | None = None, hi: int | None = None) -> int:
        v = self.value
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(f"expected an integer, got {excerpt(v)}")
        if lo is not None and v < lo:
            raise self.fail(f"expected an integer ≥ {lo}, got {excerpt(v)}")
        if hi is not None and v > hi:
            raise self.fail(f"expected an integer ≤ {hi}, got {excerpt(v)}")
        return v

    def string(self, choices: tuple[str, ...] | None = None) -> str:
        v = self.value
        if not isinstance(v, str) or not v:
            raise self.fail(f"expected a non-empty string, got {excerpt(v)}")
        if choices is not None and v not in choices:
            raise self.fail(f"expected one of {list(choices)}, got {excerpt(v)}")
        return v

    def boolean(self) -> bool:
        if not isinstance(self.value, bool):
            raise self.fail(f"expected true or false, got {excerpt(self.value)}")
        return self.value

    def vector(self, n: int = 3, *, nonzero: bool = False, unit: str = "") -> tuple[float, ...]:
        v = self.value
        if not isinstance(v, list) or len(v) != n:
            raise self.fail(f"expected a list of {n} numbers{' (' + unit + ')' if unit else ''}, got {excerpt(v)}")
        out = tuple(Node(x, f"{self.path}[{i}]", self.source).number() for i, x in enumerate(v))
        if nonzero and not 0.0 < sum(x * x for x in out) < math.inf:    # [1e-300, 0, 0] underflows
            raise self.fail(f"expected a non-zero vector (a direction; its squared length a positive, finite "
                            f"double), got {excerpt(v)}")
        return out

    def numbers(self, *, min_len: int = 1) -> tuple[float, ...]:
        v = self.value
        if not isinstance(v, list) or len(v) < min_len:
            raise self.fail(f"expected a list of at least {min_len} numbers, got {excerpt(v)}")
        return tuple(Node(x, f"{self.path}[{i}]", self.source).number() for i, x in enumerate(v))

    def name_in(self, table: dict, what: str) -> str:
        name = self.string()
        if name not in table:
            raise self.fail(f"unknown {what} {excerpt(name)}; defined: {name_list(sorted(table))}")
        return name


def _typed(value: Any) -> str:
    """A bounded excerpt that also names a scalar's type (containers name theirs already)."""
    text = excerpt(value)
    return text if isinstance(value, (list, tuple, dict)) else f"{type(value).__name__} {text}"
