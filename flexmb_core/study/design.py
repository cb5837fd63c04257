"""The design of a study: which parameter values each run gets.

``--param KEY=VALUES``: ``KEY`` is a scene key path (the syntax of ``flexmb replay --override``);
``VALUES`` is

* a list ``a,b,c`` (commas inside brackets belong to the value: ``[0.6,1.6],[0.5,1.7]``) — the
  list parameters are crossed (full factorial, the first ``--param`` varies slowest);
* a range ``LO:HI`` — sampled: ``N`` points of a Latin hypercube (:mod:`scipy.stats.qmc`, seeded)
  over all range parameters, mapped through ``--distribution`` (uniform, loguniform, or normal =
  a normal of mean (LO+HI)/2 and σ = (HI−LO)/4 truncated to [LO, HI]). Integer bounds (``2:8``)
  give integers, uniformly over LO…HI. With list parameters too, every list combination gets the
  same ``N`` samples.

A single value (``KEY=v``) is a fixed edit of every run.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import excerpt, thousands
from ..scene.overrides import OverrideError, split_key

DISTRIBUTIONS = ("uniform", "loguniform", "normal")
MAX_RUNS = 1_000_000         # runs of one sweep at most: each is a whole run (a table row, a file each)
_NUMBER = re.compile(r"^\s*[-+]?(\d[\d_]*\.?\d*|\.\d+)([eE][-+]?\d+)?\s*$")
_INTEGER = re.compile(r"^\s*[-+]?\d+\s*$")


@dataclass(frozen=True)
class Param:
    """One ``--param``: a key path and either listed values or a range."""

    key: str                      # "materials.steel.E"
    path: tuple[str, ...]
    values: tuple[Any, ...] = ()  # list parameters
    low: float = math.nan         # range parameters
    high: float = math.nan
    integer: bool = False

    @property
    def is_range(self) -> bool:
        return not self.values


def parse_param(item: str, flag: str = "--param") -> Param:
    """``"KEY=a,b,c"`` or ``"KEY=LO:HI"`` → :class:`Param`.

    Raises
    ------
    OverrideError
        On a missing ``=``, an empty key or value, or a range whose bounds are not numbers with LO < HI.
    """
    from ..scene.loader import parse_yaml

    if "=" not in item:
        raise OverrideError(f"{flag} {item!r}: expected KEY.PATH=VALUES, e.g. materials.steel.E=2.0e11,2.1e11 "
                            "or materials.steel.E=2.0e11:2.2e11")
    key, raw = item.split("=", 1)
    path = split_key(key)
    if not path:
        raise OverrideError(f"{flag} {item!r}: empty key")
    key = ".".join(path)
    parts = raw.split(":")
    if len(parts) == 2 and all(_NUMBER.match(p) for p in parts):
        lo, hi = (float(p.replace("_", "")) for p in parts)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise OverrideError(f"{flag} {item!r}: a range needs finite bounds LO < HI, got {lo:g}:{hi:g}")
        return Param(key, tuple(path), low=lo, high=hi, integer=all(_INTEGER.match(p) for p in parts))
    if ":" in raw and not any(c in raw for c in "[{,"):
        # a bare LO:HI that is no range of two numbers was meant as one: as a YAML string it would
        # become a single value, and `--samples` would then say that no range was given
        raise OverrideError(f"{flag} {excerpt(item, 80)}: a range needs two numbers LO:HI "
                            f"(e.g. 2.0e11:2.2e11), got {excerpt(raw, 40)}")
    values = tuple(parse_yaml(v) for v in split_values(raw))
    if not values or any(v is None for v in values):
        raise OverrideError(f"{flag} {item!r}: expected a value list a,b,c or a range LO:HI after '='")
    return Param(key, tuple(path), values=values)


def split_values(raw: str) -> list[str]:
    """Split at commas outside brackets and braces: ``"[1,2],[3,4]"`` → ``["[1,2]", "[3,4]"]``."""
    out, depth, cur = [], 0, []
    for ch in raw:
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        if ch == "," and depth == 0:
            out.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    out.append("".join(cur))
    return [s.strip() for s in out if s.strip()]


def latin_hypercube(params: list[Param], samples: int, *, distribution: str = "uniform",
                    seed: int = 0) -> np.ndarray:
    """``samples`` points over the range parameters: ``(samples, len(params))``, each within its
    [low, high] (integers for integer parameters). The same seed gives the same points."""
    from scipy.stats import qmc

    if distribution not in DISTRIBUTIONS:
        raise OverrideError(f"--distribution {distribution!r}: expected one of {list(DISTRIBUTIONS)}")
    if samples < 1:
        raise OverrideError(f"--samples must be a positive integer, got {samples}")
    u = qmc.LatinHypercube(d=len(params), rng=np.random.default_rng(seed)).random(samples)  # (n, d) in [0, 1)
    out = np.empty_like(u)
    for j, p in enumerate(params):
        out[:, j] = _map(u[:, j], p, distribution)
    return out


def _map(u: np.ndarray, p: Param, distribution: str) -> np.ndarray:
    lo, hi = p.low, p.high
    if p.integer:                                   # uniform over the integers lo … hi
        return np.minimum(np.floor(lo + u * (hi - lo + 1.0)), hi)
    if distribution == "loguniform":
        if lo <= 0:
            raise OverrideError(f"--param {p.key}={lo:g}:{hi:g}: a loguniform range needs LO > 0")
        return np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo)))
    if distribution == "normal":
        from scipy.stats import truncnorm

        mean, sigma = 0.5 * (lo + hi), 0.25 * (hi - lo)
        return np.clip(truncnorm.ppf(u, -2.0, 2.0, loc=mean, scale=sigma), lo, hi)
    return lo + u * (hi - lo)


def design(params: list[Param], *, samples: int | None = None, distribution: str = "uniform",
           seed: int = 0) -> list[dict[str, Any]]:
    """Every run's parameter values ``{key: value}``, in run order.

    Raises
    ------
    OverrideError
        When a key is given twice, ranges come without ``samples`` or ``samples`` without ranges.
    """
    keys = [p.key for p in params]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise OverrideError(f"--param: key(s) {dup} given more than once")
    lists = [p for p in params if not p.is_range]
    ranges = [p for p in params if p.is_range]
    if ranges and samples is None:
        raise OverrideError(f"--param {ranges[0].key}={ranges[0].low:g}:{ranges[0].high:g} is a range: "
                            "give --samples N (Latin hypercube) or list the values a,b,c")
    if samples is not None and not ranges:
        raise OverrideError("--samples needs at least one range parameter KEY=LO:HI")
    count = math.prod(len(p.values) for p in lists) * (samples if ranges else 1)
    if count > MAX_RUNS:             # counted before a list of them is built (10⁹ combinations: gigabytes)
        sizes = " × ".join([str(len(p.values)) for p in lists] + ([f"{samples} samples"] if ranges else []))
        raise OverrideError(f"--param: {sizes} = {thousands(count)} runs; at most {thousands(MAX_RUNS)} "
                            "(fewer values per list, or a Latin hypercube over ranges with --samples)")
    points = latin_hypercube(ranges, samples, distribution=distribution, seed=seed) if ranges else np.zeros((1, 0))
    runs = []
    for combo in itertools.product(*(p.values for p in lists)):
        for row in points:
            values = dict(zip((p.key for p in lists), combo))
            values.update({p.key: (int(x) if p.integer else float(x)) for p, x in zip(ranges, row)})
            runs.append({k: values[k] for k in keys})
    return runs
