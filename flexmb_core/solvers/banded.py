"""Sparse LU without pivoting on a fixed, structurally symmetric pattern, in envelope storage.

Every Newton iteration factors ``A = K + c M`` on the same CSR pattern, so everything that depends
only on the pattern is done once, in :class:`SkylineLU`'s constructor:

1. **Ordering.** Several permutations are tried and the one with the smallest estimated factor
   cost is kept: the given numbering, reverse Cuthill–McKee (``scipy.sparse.csgraph``) and
   "arrowhead" orderings, where the DOFs of high-degree nodes (the joints where several chains meet,
   e.g. the platform vertices of a Stewart platform) are numbered last and each remaining chain is
   numbered by RCM, oriented so that its end next to a joint comes last. For a chain RCM is already
   optimal; for chains that meet at joints RCM interleaves the chains (its level sets cross all legs
   at once) and the arrowhead ordering is several times cheaper.
2. **Storage.** Row ``i`` of the permuted matrix has envelope ``[first[i], i]``. ``L`` (unit lower)
   row ``i`` and ``U`` column ``i`` (diagonal included) are stored next to each other:
   ``L[i, k] = env[lbase[i] + k]`` and ``U[k, i] = env[ubase[i] + k]`` for ``first[i] <= k``.
   The envelope holds the full fill of an LU without pivoting.
3. **Symbolic factorization.** The exact structure of each row of ``L`` (the row subtree of the
   elimination tree) is stored as runs of consecutive columns (``seg_lo[s]:seg_hi[s]`` for
   ``s`` in ``seg_ptr[i]:seg_ptr[i+1]``). Within a chain a row is one run; the row of a joint
   has one run per chain it touches, and the structural zeros between the runs are never computed,
   so joints cost what the true fill costs, not what their (wide) envelope would.
4. **Scatter map.** ``slot[p]`` is the position in ``env`` of CSR data entry ``p``.

:meth:`SkylineLU.factor` then zeroes the structural entries, scatters the CSR values and runs a
row-by-row Doolittle factorization whose inner products are contiguous in memory; its cost is the
sum over the factor entries of the overlap of their two envelopes (≈ Σ width² for a chain).
:meth:`SkylineLU.solve` does the permuted forward and back substitution without allocating.

No pivoting is done. That is backward stable for symmetric positive definite and diagonally
dominant matrices; for symmetric indefinite or non-symmetric matrices it is safe as long as no
pivot becomes small — the factor reports the smallest pivot (:attr:`SkylineLU.min_pivot_ratio`)
and raises :class:`SingularPivotError` on a (near-)zero or non-finite pivot so the caller can fall
back to a pivoting solver (scipy's ``splu``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.csgraph import connected_components, reverse_cuthill_mckee

from ..errors import FlexmbError

__all__ = ["SkylineLU", "SingularPivotError", "NotFactoredError"]

# Floating-point flags for the hot kernels: reassociation lets LLVM vectorize the inner products,
# contraction allows FMA. No "nnan"/"ninf", so the non-finite pivot test stays valid.
_FASTMATH = {"reassoc", "contract"}


class SingularPivotError(FlexmbError, RuntimeError):
    """A pivot of the LU without pivoting is (near) zero or not finite.

    Parameters
    ----------
    row : int
        Row of the *original* (unpermuted) matrix whose pivot failed.
    step : int
        Elimination step (row of the permuted matrix).
    pivot : float
        The pivot value.
    threshold : float
        ``pivot_tol * max |diag(A)|``; the pivot failed because ``|pivot| <= threshold`` or it is
        not finite.
    """

    def __init__(self, row: int, step: int, pivot: float, threshold: float):
        self.row = int(row)
        self.step = int(step)
        self.pivot = float(pivot)
        self.threshold = float(threshold)
        super().__init__(
            f"LU without pivoting: pivot {self.pivot:.6g} at elimination step {self.step} "
            f"(matrix row {self.row}) is {'not finite' if not np.isfinite(self.pivot) else 'too small'}"
            f" (threshold |pivot| > {self.threshold:.3g}); the matrix is singular, or needs pivoting — "
            f"fall back to a pivoting solver such as scipy.sparse.linalg.splu")


class NotFactoredError(FlexmbError, RuntimeError):
    """``solve`` was called before a successful ``factor``."""


# ---------------------------------------------------------------------------------------------
# Pattern analysis (run once per pattern)
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def _symbolic(n, ptr, idx):
    """Envelope and exact row structure of ``L`` for a structurally symmetric pattern.

    Parameters
    ----------
    n : int
        Matrix size.
    ptr : int64 (n + 1,)
        CSR row pointer of the (symmetrized, permuted) pattern.
    idx : int64 (nnz,)
        CSR column indices, any order within a row.

    Returns
    -------
    first : int64 (n,)
        First column of the envelope of row ``i`` (``first[i] <= i``).
    seg_ptr : int64 (n + 1,)
        Runs of row ``i`` of ``L`` are ``seg_ptr[i]:seg_ptr[i+1]``.
    seg_lo, seg_hi : int64 (nseg,)
        Run ``s`` covers columns ``seg_lo[s] <= k < seg_hi[s]`` (all ``< i``).
    """
    parent = np.full(n, -1, np.int64)
    ancestor = np.full(n, -1, np.int64)
    first = np.arange(n).astype(np.int64)
    # elimination tree (Liu), with path compression through `ancestor`
    for i in range(n):
        for p in range(ptr[i], ptr[i + 1]):
            k = idx[p]
            if k < first[i]:
                first[i] = k
            if k >= i:
                continue
            r = k
            while ancestor[r] != -1 and ancestor[r] != i:
                nxt = ancestor[r]
                ancestor[r] = i
                r = nxt
            if ancestor[r] == -1:
                ancestor[r] = i
                parent[r] = i
    # row structures: the path from each k < i in row i up the tree to i
    mark = np.full(n, -1, np.int64)
    buf = np.empty(n, np.int64)
    seg_ptr = np.zeros(n + 1, np.int64)
    cap = 4 * n + 16
    seg_lo = np.empty(cap, np.int64)
    seg_hi = np.empty(cap, np.int64)
    nseg = 0
    for i in range(n):
        cnt = 0
        mark[i] = i
        for p in range(ptr[i], ptr[i + 1]):
            r = idx[p]
            if r >= i:
                continue
            while mark[r] != i:
                mark[r] = i
                buf[cnt] = r
                cnt += 1
                r = parent[r]
        cols = np.sort(buf[:cnt])
        j = 0
        while j < cnt:
            lo = cols[j]
            while j + 1 < cnt and cols[j + 1] == cols[j] + 1:
                j += 1
            if nseg == cap:
                cap *= 2
                seg_lo = np.concatenate((seg_lo, np.empty(cap - nseg, np.int64)))
                seg_hi = np.concatenate((seg_hi, np.empty(cap - nseg, np.int64)))
            seg_lo[nseg] = lo
            seg_hi[nseg] = cols[j] + 1
            nseg += 1
            j += 1
        seg_ptr[i + 1] = nseg
    return first, seg_ptr, seg_lo[:nseg].copy(), seg_hi[:nseg].copy()


@njit(cache=True)
def _factor_cost(first, seg_ptr, seg_lo, seg_hi):
    """Multiply–adds of :func:`_factor_kernel` for a given symbolic structure.

    Parameters
    ----------
    first : int64 (n,)
    seg_ptr : int64 (n + 1,)
    seg_lo, seg_hi : int64 (nseg,)

    Returns
    -------
    fma : int64
        Multiply–adds of the inner products (both ``L`` and ``U``).
    nnz : int64
        Strictly lower entries of ``L`` (= strictly upper entries of ``U``).
    """
    n = first.shape[0]
    fma = 0
    nnz = 0
    for i in range(n):
        fi = first[i]
        for s in range(seg_ptr[i], seg_ptr[i + 1]):
            for c in range(seg_lo[s], seg_hi[s]):
                nnz += 1
                for t in range(seg_ptr[c], seg_ptr[c + 1]):
                    k0 = max(seg_lo[t], fi)
                    if seg_hi[t] > k0:
                        fma += 2 * (seg_hi[t] - k0)
            fma += seg_hi[s] - seg_lo[s]
    return fma, nnz


# ---------------------------------------------------------------------------------------------
# Hot kernels
# ---------------------------------------------------------------------------------------------

@njit(cache=True, fastmath=_FASTMATH)
def _factor_kernel(data, slot, diag_pos, lbase, ubase, first, seg_ptr, seg_lo, seg_hi, env,
                   inv_diag, pivot_tol, stats):
    """Scatter CSR values into the envelope and factor ``P A Pᵀ = L U`` in place, no pivoting.

    Parameters
    ----------
    data : float64 (nnz,)
        CSR values of ``A`` on the fixed pattern.
    slot : int64 (nnz,)
        Position in ``env`` of each CSR entry.
    diag_pos : int64 (n,)
        CSR position of ``A[i, i]`` (original numbering), ``-1`` if not in the pattern.
    lbase, ubase : int64 (n,)
        ``L[i, k] = env[lbase[i] + k]``, ``U[k, i] = env[ubase[i] + k]`` (permuted numbering).
    first : int64 (n,)
        First envelope column of each permuted row.
    seg_ptr : int64 (n + 1,)
    seg_lo, seg_hi : int64 (nseg,)
        Exact structure of the rows of ``L`` as runs of columns.
    env : float64 (nenv,)
        Envelope storage, overwritten with ``L`` and ``U``. Entries outside the structure must be
        zero on entry (they are never written).
    inv_diag : float64 (n,)
        Output: ``1 / U[i, i]``.
    pivot_tol : float
        Relative pivot threshold.
    stats : float64 (3,)
        Output: ``max |diag(A)|``, ``min |pivot|`` over the steps done, the failing pivot.

    Returns
    -------
    int
        ``-1`` on success, else the elimination step whose pivot failed.
    """
    n = first.shape[0]
    # zero the structural entries, then scatter
    for i in range(n):
        li = lbase[i]
        ui = ubase[i]
        for s in range(seg_ptr[i], seg_ptr[i + 1]):
            for k in range(seg_lo[s], seg_hi[s]):
                env[li + k] = 0.0
                env[ui + k] = 0.0
        env[ui + i] = 0.0
    for p in range(data.shape[0]):
        env[slot[p]] += data[p]
    dmax = 0.0
    for i in range(n):
        p = diag_pos[i]
        if p >= 0:
            a = abs(data[p])
            if a > dmax:
                dmax = a
    thresh = pivot_tol * dmax
    stats[0] = dmax
    pmin = np.inf
    for i in range(n):
        li = lbase[i]
        ui = ubase[i]
        fi = first[i]
        d = env[ui + i]
        for s in range(seg_ptr[i], seg_ptr[i + 1]):
            for c in range(seg_lo[s], seg_hi[s]):
                lc = lbase[c]
                uc = ubase[c]
                sl = env[li + c]    # A[i, c] - Σ L[i, k] U[k, c]
                su = env[ui + c]    # A[c, i] - Σ L[c, k] U[k, i]
                for t in range(seg_ptr[c], seg_ptr[c + 1]):
                    k0 = max(seg_lo[t], fi)
                    for k in range(k0, seg_hi[t]):
                        sl -= env[li + k] * env[uc + k]
                        su -= env[lc + k] * env[ui + k]
                lic = sl * inv_diag[c]
                env[li + c] = lic
                env[ui + c] = su
                d -= lic * su
        env[ui + i] = d
        a = abs(d)
        if not (a > thresh) or not np.isfinite(d):
            stats[1] = min(pmin, a)
            stats[2] = d
            return i
        if a < pmin:
            pmin = a
        inv_diag[i] = 1.0 / d
    stats[1] = pmin
    stats[2] = 0.0
    return -1


@njit(cache=True, fastmath=_FASTMATH)
def _solve_kernel(b, perm, lbase, ubase, seg_ptr, seg_lo, seg_hi, env, inv_diag, work, out):
    """Solve ``A x = b`` with the factors of ``P A Pᵀ = L U``.

    Parameters
    ----------
    b : float64 (n,)
        Right-hand side (original numbering).
    perm : int64 (n,)
        ``perm[i]`` is the original index of permuted unknown ``i``.
    lbase, ubase : int64 (n,)
    seg_ptr : int64 (n + 1,)
    seg_lo, seg_hi : int64 (nseg,)
    env : float64 (nenv,)
        Factors from :func:`_factor_kernel`.
    inv_diag : float64 (n,)
    work : float64 (n,)
        Scratch.
    out : float64 (n,)
        Output ``x`` (original numbering); may be the same array as ``b``.
    """
    n = perm.shape[0]
    for i in range(n):
        work[i] = b[perm[i]]
    # L y = P b   (row-oriented, unit diagonal)
    for i in range(n):
        li = lbase[i]
        acc = work[i]
        for s in range(seg_ptr[i], seg_ptr[i + 1]):
            for k in range(seg_lo[s], seg_hi[s]):
                acc -= env[li + k] * work[k]
        work[i] = acc
    # U z = y   (column-oriented)
    for i in range(n - 1, -1, -1):
        ui = ubase[i]
        xi = work[i] * inv_diag[i]
        work[i] = xi
        for s in range(seg_ptr[i], seg_ptr[i + 1]):
            for k in range(seg_lo[s], seg_hi[s]):
                work[k] -= env[ui + k] * xi
    for i in range(n):
        out[perm[i]] = work[i]


# ---------------------------------------------------------------------------------------------
# Orderings (Python, once per pattern)
# ---------------------------------------------------------------------------------------------

def _arrowhead_ordering(sym: sp.csr_matrix, is_sep: np.ndarray) -> np.ndarray:
    """Non-separator components by RCM, each oriented so its separator-side end is last; the
    components touching fewest separator DOFs first; separators last, by first neighbour."""
    n = sym.shape[0]
    keep = np.flatnonzero(~is_sep)
    sub = sym[keep][:, keep].tocsr()
    ncomp, labels = connected_components(sub, directed=False)
    rcm = reverse_cuthill_mckee(sub, symmetric_mode=True)   # components stay contiguous
    # DOFs adjacent to a separator, and how many separator DOFs each component touches
    sep_adj = np.asarray(sym[:, np.flatnonzero(is_sep)].getnnz(axis=1) > 0)[keep]
    comp_order = []
    for comp in range(ncomp):
        seq = rcm[labels[rcm] == comp]                       # sub-indices, RCM order
        adj_pos = np.flatnonzero(sep_adj[seq])
        if adj_pos.size and adj_pos.mean() < 0.5 * (seq.size - 1):
            seq = seq[::-1]
        comp_order.append((int(sep_adj[seq].sum()), -seq.size, comp, keep[seq]))
    comp_order.sort(key=lambda t: t[:3])
    head = np.concatenate([t[3] for t in comp_order]) if comp_order else np.empty(0, np.int64)
    pos = np.full(n, n, np.int64)
    pos[head] = np.arange(head.size)
    seps = np.flatnonzero(is_sep)
    first_nb = np.array([pos[sym.indices[sym.indptr[s]:sym.indptr[s + 1]]].min() for s in seps],
                        dtype=np.int64)
    seps = seps[np.lexsort((seps, first_nb))]
    return np.concatenate((head, seps)).astype(np.int64)


def _candidate_orderings(sym: sp.csr_matrix):
    """(name, perm) pairs to compare."""
    n = sym.shape[0]
    yield "natural", np.arange(n, dtype=np.int64)
    yield "rcm", reverse_cuthill_mckee(sym, symmetric_mode=True).astype(np.int64)
    deg = np.diff(sym.indptr)
    levels = np.unique(deg)[::-1]
    tried = 0
    for d in levels[1:]:
        # separators: DOFs of degree > d (nodes shared by more elements than chain nodes are)
        is_sep = deg > d
        nsep = int(is_sep.sum())
        if nsep > 0.25 * n:
            break
        yield f"arrowhead(deg>{d})", _arrowhead_ordering(sym, is_sep)
        tried += 1
        if tried == 6:
            break


def _as_index_array(a, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim != 1 or not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"SkylineLU: {name} must be a 1-D integer array, got shape {a.shape} "
                         f"dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.int64)


# ---------------------------------------------------------------------------------------------
# The solver
# ---------------------------------------------------------------------------------------------

class SkylineLU:
    """LU without pivoting of a sparse matrix on a fixed pattern, in envelope (skyline) storage.

    Parameters
    ----------
    n : int
        Number of unknowns.
    indptr : int (n + 1,)
        CSR row pointer of the fixed pattern.
    indices : int (nnz,)
        CSR column indices. The pattern should be structurally symmetric (it is symmetrized
        internally if not; the missing entries are then treated as explicit zeros).
    pivot_tol : float, keyword-only
        A pivot ``d`` fails when ``|d| <= pivot_tol * max |diag(A)|`` or ``d`` is not finite.
    ordering : {"auto", "rcm", "natural"}, keyword-only
        ``"auto"`` keeps the cheapest of the given numbering, RCM and the arrowhead orderings.

    Attributes
    ----------
    perm : int64 (n,)
        ``perm[i]`` is the original index of the ``i``-th eliminated unknown.
    ordering_name : str
        Which candidate ordering was kept.
    min_pivot_ratio : float
        After :meth:`factor`: ``min |pivot| / max |diag(A)|`` — a cheap stability indicator
        (values far below ~1e-8 mean the no-pivoting LU may have lost accuracy).

    Notes
    -----
    Not thread-safe: :meth:`solve` uses an internal scratch vector.
    """

    def __init__(self, n: int, indptr, indices, *, pivot_tol: float = 1e-14, ordering: str = "auto"):
        n = int(n)
        if n < 1:
            raise ValueError(f"SkylineLU: n must be >= 1, got {n}")
        indptr = _as_index_array(indptr, "indptr")
        indices = _as_index_array(indices, "indices")
        if indptr.shape[0] != n + 1 or indptr[0] != 0 or np.any(np.diff(indptr) < 0) \
                or indptr[-1] != indices.shape[0]:
            raise ValueError(f"SkylineLU: indptr must be non-decreasing of length n + 1 = {n + 1} "
                             f"from 0 to len(indices) = {indices.shape[0]}, got length "
                             f"{indptr.shape[0]}, ends {indptr[0]}..{indptr[-1]}")
        if indices.size and (indices.min() < 0 or indices.max() >= n):
            raise ValueError(f"SkylineLU: column indices must lie in [0, {n}), got "
                             f"[{indices.min()}, {indices.max()}]")
        if ordering not in ("auto", "rcm", "natural"):
            raise ValueError(f"SkylineLU: ordering must be 'auto', 'rcm' or 'natural', got {ordering!r}")
        if not pivot_tol >= 0.0:
            raise ValueError(f"SkylineLU: pivot_tol must be >= 0, got {pivot_tol}")
        self.n = n
        self.nnz = int(indices.shape[0])
        self.pivot_tol = float(pivot_tol)

        a = sp.csr_matrix((np.ones(self.nnz), indices, indptr), shape=(n, n))
        sym = (a + a.T + sp.identity(n, format="csr")).tocsr()
        sym.sort_indices()
        sym.indices = sym.indices.astype(np.int64)
        sym.indptr = sym.indptr.astype(np.int64)

        best = None
        for name, perm in _candidate_orderings(sym):
            if ordering != "auto" and name != ordering:
                continue
            iperm = np.empty(n, np.int64)
            iperm[perm] = np.arange(n, dtype=np.int64)
            ps = sym[perm][:, perm].tocsr()
            sym_p = _symbolic(n, ps.indptr.astype(np.int64), ps.indices.astype(np.int64))
            fma, nnz_l = _factor_cost(*sym_p)
            cost = int(fma) + 4 * int(nnz_l)       # inner-product work + per-entry overhead
            if best is None or cost < best[0]:
                best = (cost, name, perm, iperm, sym_p, int(fma), int(nnz_l))
        _, self.ordering_name, perm, iperm, sym_p, self.factor_fma, nnz_l = best
        self.perm = perm
        self._iperm = iperm
        self._first, self._seg_ptr, self._seg_lo, self._seg_hi = sym_p
        self.nnz_factor = 2 * nnz_l + n

        # envelope layout: row i stores L[i, first:i] then U[first:i+1, i]
        w = np.arange(n, dtype=np.int64) - self._first            # (n,) strictly-lower widths
        start = np.zeros(n + 1, np.int64)
        np.cumsum(2 * w + 1, out=start[1:])
        self._lbase = np.ascontiguousarray(start[:-1] - self._first)
        self._ubase = np.ascontiguousarray(start[:-1] + w - self._first)
        self._env = np.zeros(int(start[-1]), np.float64)

        # scatter map: CSR position -> envelope slot
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(indptr))
        pr, pc = iperm[rows], iperm[indices]
        self._slot = np.ascontiguousarray(
            np.where(pr > pc, self._lbase[pr] + pc, self._ubase[pc] + pr).astype(np.int64))
        diag_pos = np.full(n, -1, np.int64)
        is_diag = rows == indices
        diag_pos[rows[is_diag]] = np.flatnonzero(is_diag)
        self._diag_pos = diag_pos

        self._inv_diag = np.zeros(n, np.float64)
        self._work = np.zeros(n, np.float64)
        self._stats = np.zeros(3, np.float64)
        self._factored = False

    # -- properties -----------------------------------------------------------------------------

    @property
    def bandwidth(self) -> int:
        """Largest envelope half-width ``max_i (i - first[i])`` of the permuted matrix."""
        return int(np.max(np.arange(self.n) - self._first))

    @property
    def profile_size(self) -> int:
        """Stored envelope entries: ``L`` and ``U`` envelopes plus the diagonal."""
        return int(self._env.shape[0])

    @property
    def min_pivot_ratio(self) -> float:
        """``min |pivot| / max |diag(A)|`` of the last factorization (``nan`` before one)."""
        if not self._factored or self._stats[0] == 0.0:
            return float("nan")
        return float(self._stats[1] / self._stats[0])

    # -- numerics -------------------------------------------------------------------------------

    def factor(self, data) -> None:
        """Factor the matrix whose CSR values on the fixed pattern are ``data``.

        Parameters
        ----------
        data : float64 (nnz,)

        Raises
        ------
        SingularPivotError
            A pivot is not finite or ``|pivot| <= pivot_tol * max |diag(A)|``.
        """
        data = np.ascontiguousarray(data, dtype=np.float64)
        if data.shape != (self.nnz,):
            raise ValueError(f"SkylineLU.factor: data must have shape ({self.nnz},), got {data.shape}")
        self._factored = False
        step = _factor_kernel(data, self._slot, self._diag_pos, self._lbase, self._ubase,
                              self._first, self._seg_ptr, self._seg_lo, self._seg_hi, self._env,
                              self._inv_diag, self.pivot_tol, self._stats)
        if step >= 0:
            raise SingularPivotError(self.perm[step], step, self._stats[2],
                                     self.pivot_tol * self._stats[0])
        self._factored = True

    def solve(self, b, out=None) -> np.ndarray:
        """Solve ``A x = b`` with the last factorization.

        Parameters
        ----------
        b : float64 (n,)
        out : float64 (n,), C-contiguous, optional
            Where to write ``x`` (may be ``b`` itself). Nothing is allocated when given and ``b``
            is already float64 and C-contiguous.

        Returns
        -------
        x : float64 (n,)
            ``out`` if given.
        """
        if not self._factored:
            raise NotFactoredError("SkylineLU.solve: no valid factorization; call factor(data) "
                                   "first (the last factor may have raised SingularPivotError)")
        b = np.ascontiguousarray(b, dtype=np.float64)
        if b.shape != (self.n,):
            raise ValueError(f"SkylineLU.solve: b must have shape ({self.n},), got {b.shape}")
        if out is None:
            out = np.empty(self.n, np.float64)
        elif not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.shape == (self.n,)
                  and out.flags.c_contiguous and out.flags.writeable):
            raise ValueError(f"SkylineLU.solve: out must be a writable C-contiguous float64 array "
                             f"of shape ({self.n},)")
        _solve_kernel(b, self.perm, self._lbase, self._ubase, self._seg_ptr, self._seg_lo,
                      self._seg_hi, self._env, self._inv_diag, self._work, out)
        return out

    def __repr__(self) -> str:
        return (f"SkylineLU(n={self.n}, ordering={self.ordering_name!r}, bandwidth={self.bandwidth}, "
                f"profile_size={self.profile_size}, nnz_factor={self.nnz_factor}, "
                f"factor_fma={self.factor_fma})")
