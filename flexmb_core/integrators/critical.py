"""Critical points of a static equilibrium path, from the signs of the tangent's pivots.

A symmetric tangent factored as L D Lᵀ (an LU without pivoting, :class:`~flexmb_core.solvers.banded.SkylineLU`)
has as many negative pivots as negative eigenvalues (Sylvester's law of inertia), so the count
changes exactly where an eigenvalue crosses zero between two converged states: a critical point.
With Lagrange multipliers (rigid corners, hinges, ties) the system is a saddle point matrix
[[K, Gᵀ], [G, 0]]; eliminating the multipliers last, its inertia is that of K reduced to the
constraints' null space plus one negative pivot per multiplier, a constant — changes still mark
the critical points of the constrained structure.

:class:`TangentLU` factors, solves and counts; :func:`classify` names what a change of the count was:

- a **limit point** when the load factor has an extremum there (its derivative along the path,
  dλ/ds from the tangent at each converged point, changes sign): ``load_maximum`` /
  ``load_minimum``, with the load factor and displacement at the extremum of the cubic Hermite
  interpolants λ(s), u(s) between the two points (values and tangents: error O(Δs⁴));
- a **bifurcation** otherwise: ``stability_loss`` (one more negative pivot) or ``stability_gain``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ..model.model import Model
from ..solvers.banded import STATIC_PIVOT, SkylineLU


class TangentLU:
    """LU of the system tangent (CSR values on ``model``'s pattern) that also counts its negative pivots.

    Without multipliers the skyline LU keeps its cheapest ordering. With multipliers the free DOFs
    are numbered first (reverse Cuthill–McKee) and the multipliers last, so no zero pivot of the
    constraint block is met before the DOFs it couples. A (near-)zero pivot met anyway is replaced
    by a small one of its sign (static pivoting, :class:`~flexmb_core.solvers.banded.SkylineLU`)
    and the count is unknown (``None``); the solves of such factors, and of factors with a tiny
    pivot (a model without multipliers next to a critical point, whose count stands), are refined
    against the tangent itself (:meth:`~flexmb_core.solvers.banded.SkylineLU.refine`). Near a
    critical point that is what a solve with partial pivoting gave (SuperLU did these solves until
    2026-11-29: ``tests/verification/test_path_following.py`` traces the same paths).

    Attributes
    ----------
    negative_pivots : int | None — of the last factorization.
    """

    def __init__(self, model: Model, *, min_pivot_ratio: float = 1e-10):
        n, nf = model.nsys, model.nfree
        self.min_pivot_ratio = min_pivot_ratio
        self.negative_pivots: int | None = None
        self._suspect = False
        self._matrix = np.zeros(model.nnz)        # the suspect factors' matrix (permuted), to refine against
        self._b = np.zeros(n)
        self._perm: np.ndarray | None = None
        if model.n_multipliers == 0:
            self.lu = SkylineLU(n, model.indptr, model.indices, static_pivot=STATIC_PIVOT)
            return
        ones = sp.csr_matrix((np.ones(model.nnz), model.indices, model.indptr), shape=(n, n))
        kff = ones[:nf, :nf]
        order = reverse_cuthill_mckee((kff + kff.T).tocsr(), symmetric_mode=True)
        perm = np.concatenate([np.asarray(order, dtype=np.int64), np.arange(nf, n, dtype=np.int64)])
        # permute a matrix whose values are the CSR positions: its data is the gather map
        pos = sp.csr_matrix((np.arange(1, model.nnz + 1, dtype=float), model.indices, model.indptr),
                            shape=(n, n))[perm][:, perm].tocsr()
        pos.sort_indices()
        self._perm = perm
        self._map = np.ascontiguousarray(pos.data.astype(np.int64) - 1)
        self.lu = SkylineLU(n, pos.indptr.astype(np.int64), pos.indices.astype(np.int64), ordering="natural",
                            static_pivot=STATIC_PIVOT)

    def factor(self, kdata: np.ndarray) -> None:
        """Factor the tangent ``kdata (nnz,)``; ``RuntimeError`` when it cannot (a non-finite
        pivot, a zero matrix)."""
        data = kdata
        if self._perm is not None:
            np.take(kdata, self._map, out=self._matrix)
            data = self._matrix
        self.lu.factor(data)
        replaced = self.lu.replaced_pivots > 0
        self.negative_pivots = None if replaced else self.lu.negative_pivots
        # with multipliers the last pivots are Schur complements −G K⁻¹ Gᵀ, small by their units
        self._suspect = replaced or (self._perm is None and self.lu.min_pivot_ratio < self.min_pivot_ratio)
        if self._suspect:
            if data is not self._matrix:
                self._matrix[:] = data

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``x (nsys,)`` with the last factorization (refined when its factors are suspect: the
        best solution refinement reaches, which the caller's Newton then judges)."""
        bp = b if self._perm is None else np.take(b, self._perm, out=self._b)
        y = self.lu.solve(bp)
        if self._suspect:
            self.lu.refine(self._matrix, bp, y)
        if self._perm is None:
            return y
        x = np.empty_like(y)
        x[self._perm] = y
        return x

    def count(self, kdata: np.ndarray) -> int | None:
        """Factor ``kdata`` and return its negative pivots (``None``: unknown or singular)."""
        try:
            self.factor(kdata)
        except RuntimeError:
            return None
        return self.negative_pivots


@dataclass
class PathPoint:
    """One converged state of a traced path: increment ``step`` (0: the start), load factor
    ``lam``, monitored displacement ``u`` (m, nan without a monitor), path length ``s`` (m),
    Newton ``iterations``, the tangent's ``negative_pivots`` (None: unknown) and the path's
    tangent there in the direction of travel, ``dlam_ds`` (1/m) and ``du_ds`` (–)."""

    step: int
    lam: float
    u: float
    s: float
    iterations: int
    negative_pivots: int | None
    dlam_ds: float = math.nan
    du_ds: float = math.nan


def _hermite(s0: float, s1: float, y0: float, y1: float, d0: float, d1: float, s: float) -> float:
    """The cubic Hermite interpolant of (s0, y0, y0'), (s1, y1, y1') at ``s``."""
    h = s1 - s0
    t = (s - s0) / h
    return ((2 * t**3 - 3 * t**2 + 1) * y0 + (t**3 - 2 * t**2 + t) * h * d0
            + (-2 * t**3 + 3 * t**2) * y1 + (t**3 - t**2) * h * d1)


def _vertex(p0: PathPoint, p1: PathPoint) -> tuple[float, float]:
    """Load factor and displacement where dλ/ds of the Hermite cubic λ(s) on [p0.s, p1.s]
    vanishes (dλ/ds changes sign between the two points)."""
    h = p1.s - p0.s
    if not h > 0.0:
        return p1.lam, p1.u
    # λ'(t)/… on t ∈ [0, 1]: a t² + b t + c with the Hermite basis derivatives
    d0, d1 = p0.dlam_ds * h, p1.dlam_ds * h
    dy = p1.lam - p0.lam
    a = 6 * -dy + 3 * d0 + 3 * d1
    b = 6 * dy - 4 * d0 - 2 * d1
    c = d0
    roots = np.roots([a, b, c]) if a != 0.0 else (np.array([-c / b]) if b != 0.0 else np.array([]))
    inside = [float(r.real) for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and -1e-9 <= r.real <= 1 + 1e-9]
    t = min(inside, key=lambda r: abs(r - 0.5)) if inside else (0.0 if abs(p0.dlam_ds) < abs(p1.dlam_ds) else 1.0)
    s = p0.s + t * h
    lam = _hermite(p0.s, p1.s, p0.lam, p1.lam, p0.dlam_ds, p1.dlam_ds, s)
    u = _hermite(p0.s, p1.s, p0.u, p1.u, p0.du_ds, p1.du_ds, s) if math.isfinite(p0.u) else math.nan
    return lam, u


def _entry(step: int, lam: float, u: float, kind: str, before: int, after: int) -> dict:
    return {"step": step, "load_factor": float(lam), "displacement": float(u) if np.isfinite(u) else None,
            "kind": kind, "negative_pivots": [before, after]}


def classify(points: list[PathPoint], final: bool = False) -> tuple[list[dict], list[dict]]:
    """Limit points and bifurcations of a traced path (see the module docstring).

    A change of the count between points k−1 and k is a limit point when dλ/ds changes sign
    between two consecutive points of k−2 … k+1. Returns ``(limit_points, bifurcations)``, each a
    list of ``{step, load_factor, displacement, kind, negative_pivots: [before, after]}`` (``step``:
    the first point past it). Unless ``final``, a change at the last point waits for the next one.
    """
    limits: list[dict] = []
    bifs: list[dict] = []
    known = [i for i, p in enumerate(points) if p.negative_pivots is not None]
    for ia, ib in zip(known, known[1:]):
        a, b = points[ia], points[ib]
        if a.negative_pivots == b.negative_pivots:
            continue
        if ib == len(points) - 1 and not final:
            continue
        window = range(max(ia - 1, 0), min(ib + 1, len(points) - 1))
        turns = [j for j in window if points[j].dlam_ds * points[j + 1].dlam_ds < 0.0]
        if turns:
            j = min(turns, key=lambda j: abs(j + 0.5 - (ia + ib) / 2))
            lam, u = _vertex(points[j], points[j + 1])
            kind = "load_maximum" if points[j].dlam_ds > 0.0 else "load_minimum"
            limits.append(_entry(points[j + 1].step, lam, u, kind, a.negative_pivots, b.negative_pivots))
        else:
            kind = "stability_loss" if b.negative_pivots > a.negative_pivots else "stability_gain"
            bifs.append(_entry(b.step, b.lam, b.u, kind, a.negative_pivots, b.negative_pivots))
    return limits, bifs
