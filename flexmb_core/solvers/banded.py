"""Sparse LU without pivoting on a fixed, structurally symmetric pattern, in envelope storage.

Every Newton iteration factors ``A = K + c M`` on the same CSR pattern, so everything that depends
only on the pattern is done once, in :class:`SkylineLU`'s constructor:

1. **Ordering.** Several permutations are tried and the one with the fewest factor multiply–adds
   is kept: the given numbering, scipy's reverse Cuthill–McKee, RCM started from a
   pseudo-peripheral vertex (George–Liu), and "arrowhead" orderings where the DOFs of high-degree
   nodes (joints where several chains meet, e.g. the platform vertices of a Stewart platform) are
   numbered last and each remaining chain is numbered by RCM, oriented so that its end next to a
   joint comes last. scipy's RCM starts from a minimum-degree vertex, which on a chain of elements
   can be in the middle (the front then runs both ways: twice the bandwidth); on chains that meet
   at joints RCM interleaves the chains, and the arrowhead ordering needs 10–40 % fewer operations
   on Stewart-platform patterns.
2. **Storage.** Row ``i`` of the permuted matrix holds ``L[i, f_i:i]`` and ``U[i, i:e_i+1]``
   contiguously, ``env[base[i] + j]`` for ``f_i <= j <= e_i`` (variable-band row storage). For a
   structurally symmetric pattern this envelope contains all the fill of an LU without pivoting.
3. **Symbolic factorization.** The exact structure of each row of ``L`` and of ``U`` is stored as
   runs of consecutive columns. Inside a chain a row is one run; the row of a joint has one run per
   chain it touches, and the zeros between the runs are never touched — joints cost their true
   fill, not their (wide) envelope.
4. **Blocks.** Consecutive pivots with nested structure (``struct(k) = {k+1} ∪ struct(k+1)``, e.g.
   the DOFs of a node or of an element interior) are grouped by up to four, so the Schur
   complement update is a rank-4 update of two contiguous rows at a time (≈ 1.5× faster than
   rank-1 updates on chains).
5. **Scatter map.** ``slot[p]`` is the position in ``env`` of CSR data entry ``p``.

:meth:`SkylineLU.factor` zeroes the structural entries, scatters the CSR values and runs a blocked
right-looking LU; its cost is ``Σ_k |struct(k)|²`` (≈ Σ width² for a chain).
:meth:`SkylineLU.solve` does the permuted forward and back substitution without allocating.

No pivoting is done. That is backward stable for symmetric positive definite and diagonally
dominant matrices; for symmetric indefinite or non-symmetric matrices it is accurate only while
no pivot becomes small relative to the entries it eliminates — :attr:`SkylineLU.min_pivot_ratio`
reports the smallest pivot. A (near-)zero pivot either raises :class:`SingularPivotError` or, with
``static_pivot`` (static pivoting, Li & Demmel 1998), is replaced by a small one of its sign; then
:meth:`SkylineLU.refine` (iterative refinement against the matrix itself) recovers the solution
and measures its backward error, which says whether the solve can be trusted.

The envelope of a joint row spans every chain numbered before it, so :attr:`SkylineLU.profile_size`
(memory) is ~10× the factor's non-zeros on Stewart patterns; that memory is zeroed once and never
touched again (structural zeros are skipped), so it costs no time.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numba import njit
from numba.extending import register_jitable
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ..errors import FlexmbError
from ..jit import KERNEL

__all__ = ["SkylineLU", "SingularPivotError", "NotFactoredError"]

# Floating-point flags of the hot kernels: reassociation lets LLVM vectorize the inner products,
# contraction allows FMA. No "nnan"/"ninf", so the non-finite pivot test stays valid.
_FASTMATH = {"reassoc", "contract"}
_MAX_BLOCK = 4
# Static pivoting (:func:`_factor_kernel`): a pivot at or below the threshold becomes
# ± STATIC_PIVOT · max |diag(A)| — √ε, Li & Demmel's choice (SuperLU_DIST), small enough that the
# factors stay those of a nearby matrix, large enough that their growth stays bounded.
STATIC_PIVOT = 2.0 ** -26
# A solve is trusted at or below this normwise backward error; :func:`_refine_kernel` stops there.
# Measured on every tangent of the test suite that the skyline LU factored with a pivot below
# 1e-10 · max |diag| (slack tendons, rigid corners, rubber beside steel, the buckled leg, the tendon
# arm): 3e-17 to 2e-16 without any sweep, as SuperLU with partial pivoting gave on the same
# matrices (4e-17 to 3e-16); a free spin link in statics (singular tangent, consistent residual)
# 3.2e-13 after refinement. A singular matrix with a residual outside its range keeps
# ω ≈ STATIC_PIVOT (7.5e-9 in tests/unit/test_banded_solver.py): the bound sits between, 30× above
# the one and 750× below the other.
BACKWARD_ERROR_TOL = 1.0e-11
# GMRES(KRYLOV_DIM) with at most REFINE_CYCLES restarts refines a solve (:func:`_refine_kernel`);
# it needs about one iteration more than the pivots replaced
KRYLOV_DIM = 20
REFINE_CYCLES = 3


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
        what = "not finite" if not np.isfinite(self.pivot) else f"too small (|pivot| <= {self.threshold:.3g})"
        super().__init__(
            f"LU without pivoting: pivot {self.pivot:.6g} of matrix row {self.row} (elimination step "
            f"{self.step}) is {what}; the matrix is singular or needs pivoting — factor with static_pivot "
            f"and refine the solves, or use a pivoting solver such as scipy.sparse.linalg.splu")


class NotFactoredError(FlexmbError, RuntimeError):
    """``solve`` was called without a successful ``factor``."""


# ---------------------------------------------------------------------------------------------
# Orderings (run once per pattern)
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def _cuthill_mckee(ptr, idx, active):
    """Cuthill–McKee order of the active subgraph, each component from a pseudo-peripheral vertex.

    Parameters
    ----------
    ptr, idx : int64 (n + 1,), (nnz,)
        Symmetric CSR pattern (sorted indices).
    active : bool (n,)
        Vertices to order.

    Returns
    -------
    order : int64 (n_active,)
        Cuthill–McKee order (reverse it for RCM); components are contiguous.
    comp_ptr : int64 (n_comp + 1,)
        Component ``c`` is ``order[comp_ptr[c]:comp_ptr[c+1]]``.
    """
    n = ptr.shape[0] - 1
    deg = np.zeros(n, np.int64)
    nact = 0
    for v in range(n):
        if active[v]:
            nact += 1
            for p in range(ptr[v], ptr[v + 1]):
                u = idx[p]
                if u != v and active[u]:
                    deg[v] += 1
    mark = np.full(n, -1, np.int64)
    placed = np.zeros(n, np.bool_)
    queue = np.empty(n, np.int64)
    order = np.empty(nact, np.int64)
    comp_ptr = np.zeros(nact + 1, np.int64)
    tmp = np.empty(n, np.int64)
    stamp = 0
    pos = 0
    ncomp = 0
    seeds = np.argsort(deg, kind="mergesort")
    for s in seeds:
        if not active[s] or placed[s]:
            continue
        # George–Liu pseudo-peripheral vertex: breadth-first level structures, restarted from a
        # minimum-degree vertex of the last level while they get deeper
        r = s
        h = 0
        cand = s
        while True:
            stamp += 1
            queue[0] = cand
            mark[cand] = stamp
            head = 0
            tail = 1
            hc = 0
            last = 0
            while head < tail:
                last = head
                level_end = tail
                hc += 1
                while head < level_end:
                    v = queue[head]
                    head += 1
                    for p in range(ptr[v], ptr[v + 1]):
                        u = idx[p]
                        if active[u] and mark[u] != stamp:
                            mark[u] = stamp
                            queue[tail] = u
                            tail += 1
            if hc <= h:
                break
            r = cand
            h = hc
            cand = queue[last]
            for q in range(last + 1, tail):
                if deg[queue[q]] < deg[cand]:
                    cand = queue[q]
        # Cuthill–McKee from r: neighbours by increasing degree (ties by index)
        order[pos] = r
        placed[r] = True
        head = pos
        pos += 1
        while head < pos:
            v = order[head]
            head += 1
            m = 0
            for p in range(ptr[v], ptr[v + 1]):
                u = idx[p]
                if active[u] and not placed[u]:
                    placed[u] = True
                    tmp[m] = u
                    m += 1
            srt = np.argsort(deg[tmp[:m]], kind="mergesort")
            for q in range(m):
                order[pos] = tmp[srt[q]]
                pos += 1
        ncomp += 1
        comp_ptr[ncomp] = pos
    return order, comp_ptr[:ncomp + 1].copy()


def _rcm_pseudo_peripheral(sym: sp.csr_matrix) -> np.ndarray:
    order, _ = _cuthill_mckee(sym.indptr, sym.indices, np.ones(sym.shape[0], np.bool_))
    return order[::-1].copy()


def _arrowhead_ordering(sym: sp.csr_matrix, is_sep: np.ndarray) -> np.ndarray:
    """Components of the graph without the separator DOFs by RCM, each oriented so that its
    separator-side end comes last, components touching fewest separator DOFs first; separator
    DOFs last, sorted by their first neighbour."""
    n = sym.shape[0]
    order, comp_ptr = _cuthill_mckee(sym.indptr, sym.indices, ~is_sep)
    sep_idx = np.flatnonzero(is_sep)
    sep_adj = np.asarray(sym[:, sep_idx].getnnz(axis=1)) > 0             # (n,)
    comps = []
    for c in range(comp_ptr.size - 1):
        seq = order[comp_ptr[c]:comp_ptr[c + 1]][::-1]                      # RCM of the component
        adj_pos = np.flatnonzero(sep_adj[seq])
        if adj_pos.size and adj_pos.mean() < 0.5 * (seq.size - 1):
            seq = seq[::-1]
        comps.append((int(sep_adj[seq].sum()), c, seq))
    comps.sort(key=lambda t: t[:2])
    head = np.concatenate([t[2] for t in comps])
    pos = np.full(n, n, np.int64)
    pos[head] = np.arange(head.size)
    first_nb = np.array([pos[sym.indices[sym.indptr[s]:sym.indptr[s + 1]]].min() for s in sep_idx],
                        dtype=np.int64)
    return np.concatenate((head, sep_idx[np.lexsort((sep_idx, first_nb))])).astype(np.int64)


def _candidate_orderings(sym: sp.csr_matrix, which: str):
    """Yield ``(name, perm)``; ``perm[i]`` is the original index of the ``i``-th unknown."""
    n = sym.shape[0]
    if which in ("auto", "natural"):
        yield "natural", np.arange(n, dtype=np.int64)
    if which in ("auto", "rcm"):
        yield "rcm", _rcm_pseudo_peripheral(sym)
    if which == "auto":
        yield "scipy-rcm", reverse_cuthill_mckee(sym, symmetric_mode=True).astype(np.int64)
        deg = np.diff(sym.indptr)
        for tried, d in enumerate(np.unique(deg)[::-1][1:]):
            is_sep = deg > d          # DOFs of nodes shared by more elements than chain nodes are
            if is_sep.sum() > 0.25 * n or tried == 6:
                break
            yield f"arrowhead(degree>{d})", _arrowhead_ordering(sym, is_sep)


def _late_last(sym: sp.csr_matrix, perm: np.ndarray, n0: int) -> np.ndarray:
    """``perm`` with the unknowns ``n0 …`` (multipliers) moved to the end, each after the last of
    its neighbours: a multiplier's pivot is then the Schur complement ``−G A⁻¹ Gᵀ`` of the
    unknowns it constrains, never its own zero diagonal."""
    head = perm[perm < n0]
    late = np.arange(n0, sym.shape[0], dtype=np.int64)
    pos = np.empty(sym.shape[0], np.int64)
    pos[head] = np.arange(head.size)
    pos[late] = -1
    last_nb = np.array([pos[sym.indices[sym.indptr[i]:sym.indptr[i + 1]]].max() for i in late], dtype=np.int64)
    return np.concatenate((head, late[np.lexsort((late, last_nb))])).astype(np.int64)


# ---------------------------------------------------------------------------------------------
# Symbolic factorization (run once per candidate ordering)
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def _to_runs(ptr, idx):
    """Compress sorted CSR rows into runs of consecutive columns.

    Parameters
    ----------
    ptr, idx : int64 (n + 1,), (nnz,)

    Returns
    -------
    run_ptr : int64 (n + 1,)
    run_lo, run_hi : int64 (nrun,)
        Row ``i`` is the union of ``[run_lo[s], run_hi[s])`` for ``s`` in ``run_ptr[i]:run_ptr[i+1]``.
    """
    n = ptr.shape[0] - 1
    nrun = 0
    for i in range(n):
        for p in range(ptr[i], ptr[i + 1]):
            if p == ptr[i] or idx[p] != idx[p - 1] + 1:
                nrun += 1
    run_ptr = np.zeros(n + 1, np.int64)
    run_lo = np.empty(nrun, np.int64)
    run_hi = np.empty(nrun, np.int64)
    s = -1
    for i in range(n):
        for p in range(ptr[i], ptr[i + 1]):
            if p == ptr[i] or idx[p] != idx[p - 1] + 1:
                s += 1
                run_lo[s] = idx[p]
            run_hi[s] = idx[p] + 1
        run_ptr[i + 1] = s + 1
    return run_ptr, run_lo, run_hi


@njit(cache=True)
def _symbolic(ptr, idx):
    """Exact structure of ``L`` (strictly lower) and ``U`` (strictly upper) of ``A = L U``.

    Parameters
    ----------
    ptr, idx : int64 (n + 1,), (nnz,)
        Structurally symmetric CSR pattern of the permuted matrix (any order within a row).

    Returns
    -------
    lptr, lidx : int64 (n + 1,), (nnz_l,)
        Columns ``j < i`` of row ``i`` of ``L``, sorted.
    uptr, uidx : int64 (n + 1,), (nnz_l,)
        Columns ``j > i`` of row ``i`` of ``U``, sorted (the transpose of the ``L`` structure).
    """
    n = ptr.shape[0] - 1
    parent = np.full(n, -1, np.int64)
    ancestor = np.full(n, -1, np.int64)
    # elimination tree (Liu), path compression through `ancestor`
    for i in range(n):
        for p in range(ptr[i], ptr[i + 1]):
            r = idx[p]
            if r >= i:
                continue
            while ancestor[r] != -1 and ancestor[r] != i:
                nxt = ancestor[r]
                ancestor[r] = i
                r = nxt
            if ancestor[r] == -1:
                ancestor[r] = i
                parent[r] = i
    # row i of L = union of the tree paths from each k < i in row i of A up to i (two passes)
    mark = np.full(n, -1, np.int64)
    lptr = np.zeros(n + 1, np.int64)
    lidx = np.empty(0, np.int64)
    for sweep in range(2):
        if sweep == 1:
            lidx = np.empty(lptr[n], np.int64)
        mark[:] = -1
        for i in range(n):
            cnt = 0
            mark[i] = i
            for p in range(ptr[i], ptr[i + 1]):
                r = idx[p]
                if r >= i:
                    continue
                while mark[r] != i:
                    mark[r] = i
                    if sweep == 1:
                        lidx[lptr[i] + cnt] = r
                    cnt += 1
                    r = parent[r]
            if sweep == 0:
                lptr[i + 1] = lptr[i] + cnt
            else:
                lidx[lptr[i]:lptr[i + 1]] = np.sort(lidx[lptr[i]:lptr[i + 1]])
    # transpose (counting sort keeps columns sorted)
    uptr = np.zeros(n + 1, np.int64)
    for p in range(lptr[n]):
        uptr[lidx[p] + 1] += 1
    for i in range(n):
        uptr[i + 1] += uptr[i]
    fill = uptr[:n].copy()
    uidx = np.empty(lptr[n], np.int64)
    for i in range(n):
        for p in range(lptr[i], lptr[i + 1]):
            j = lidx[p]
            uidx[fill[j]] = i
            fill[j] += 1
    return lptr, lidx, uptr, uidx


@njit(cache=True)
def _blocks(uptr, uidx, max_block):
    """Group consecutive pivots with nested structure ``struct(k) = {k+1} ∪ struct(k+1)``.

    Parameters
    ----------
    uptr, uidx : int64 (n + 1,), (nnz_u,)
        Sorted structure of the rows of ``U``.
    max_block : int
        Largest block.

    Returns
    -------
    blk_ptr : int64 (n_blocks + 1,)
        Block ``b`` is the pivots ``blk_ptr[b]:blk_ptr[b+1]``.
    """
    n = uptr.shape[0] - 1
    out = np.empty(n + 1, np.int64)
    out[0] = 0
    nb = 0
    k0 = 0
    for k in range(n - 1):
        a0, a1 = uptr[k], uptr[k + 1]
        b0, b1 = uptr[k + 1], uptr[k + 2]
        nested = a1 - a0 == b1 - b0 + 1 and a1 > a0 and uidx[a0] == k + 1
        if nested:
            for q in range(b1 - b0):
                if uidx[a0 + 1 + q] != uidx[b0 + q]:
                    nested = False
                    break
        if not nested or k + 1 - k0 == max_block:
            nb += 1
            out[nb] = k + 1
            k0 = k + 1
    nb += 1
    out[nb] = n
    return out[:nb + 1].copy()


# ---------------------------------------------------------------------------------------------
# Hot kernels
# ---------------------------------------------------------------------------------------------

@njit(fastmath=_FASTMATH, **KERNEL)
def _factor_kernel(data, data2, coef, slot, accumulate, zero_slots, base, lrun_ptr, lrun_lo, lrun_hi,
                   urun_ptr, urun_lo, urun_hi, blk_ptr, env, inv_diag, pivot_tol, static_pivot, stats, nlate):
    """Scatter ``A = data + coef * data2`` into the envelope and factor ``P A Pᵀ = L U`` in place,
    without pivoting.

    Parameters
    ----------
    data : float64 (nnz,)
        CSR values on the fixed pattern (e.g. the stiffness ``K``).
    data2 : float64 (nnz,)
        Second CSR values on the same pattern (e.g. the mass ``M``); ignored when ``coef == 0``.
    coef : float
        Factor of ``data2``.
    slot : int64 (nnz,)
        Position in ``env`` of each CSR entry.
    accumulate : bool
        The pattern has duplicate entries: add them up (``zero_slots`` then lists every structural
        slot) instead of assigning.
    zero_slots : int64 (nzero,)
        Structural slots to clear before the scatter (the fill, when ``accumulate`` is false).
    base : int64 (n,)
        Entry ``(i, j)`` of the permuted matrix / factors is ``env[base[i] + j]``.
    lrun_ptr, lrun_lo, lrun_hi : int64 (n + 1,), (nrun_l,), (nrun_l,)
        Structure of the rows of ``L`` (columns ``< i``) as runs.
    urun_ptr, urun_lo, urun_hi : int64 (n + 1,), (nrun_u,), (nrun_u,)
        Structure of the rows of ``U`` (columns ``> i``) as runs.
    blk_ptr : int64 (n_blocks + 1,)
        Pivot blocks (at most 4 pivots with nested structure).
    env : float64 (nenv,)
        Output: ``L`` (unit diagonal not stored) and ``U``. Entries outside the structure must be
        zero; they are never written.
    inv_diag : float64 (n,)
        Output: ``1 / U[i, i]``.
    pivot_tol : float
        Relative pivot threshold.
    static_pivot : float
        ``0``: a pivot at or below the threshold fails the factorization. ``> 0``: it is replaced
        by ``± static_pivot * max |diag(A)|`` (its own sign, + for zero) and the elimination goes on
        — static pivoting (Li & Demmel 1998): the factors are then those of a nearby matrix, and
        :func:`_refine_kernel` recovers the solution of ``A`` itself, or says it cannot.
    stats : float64 (3,)
        Output: ``max |diag(A)|``, ``min |pivot|`` of the steps done (before any replacement), and
        the failing pivot — on success, the number of pivots replaced.
    nlate : int
        The last ``nlate`` rows of the permuted matrix are Lagrange multipliers (zero diagonal
        block), eliminated after every unknown they constrain. Their rows and columns are scaled
        by ``s = 2^round(log2 max|diag(A)|)`` before the elimination and the factors scaled back
        after it (powers of two: exact), so that their pivots, the Schur complements
        ``−s² G A⁻¹ Gᵀ``, are of the size of the other pivots instead of ``1/stiffness`` — the
        pivot threshold and ``min |pivot|`` then judge them like any other pivot.

    Returns
    -------
    int
        ``-1`` on success, else the elimination step whose pivot failed.
    """
    n = base.shape[0]
    for q in range(zero_slots.shape[0]):
        env[zero_slots[q]] = 0.0
    combine = coef != 0.0
    if accumulate:
        if combine:
            for p in range(data.shape[0]):
                env[slot[p]] += data[p] + coef * data2[p]
        else:
            for p in range(data.shape[0]):
                env[slot[p]] += data[p]
    elif combine:
        for p in range(data.shape[0]):
            env[slot[p]] = data[p] + coef * data2[p]
    else:
        for p in range(data.shape[0]):
            env[slot[p]] = data[p]
    dmax = 0.0
    for i in range(n):
        a = abs(env[base[i] + i])
        if a > dmax:
            dmax = a
    thresh = pivot_tol * dmax
    stats[0] = dmax
    scale = 1.0
    if nlate > 0 and dmax > 0.0:
        scale = math.ldexp(1.0, int(round(math.log2(dmax))))
        _scale_late(n - nlate, scale, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, env)
    pmin = np.inf
    replaced = 0
    for b in range(blk_ptr.shape[0] - 1):
        k0 = blk_ptr[b]
        k1 = blk_ptr[b + 1]
        # (a) pivots of the block; rows of the block updated over their whole structure
        for p in range(k0, k1):
            bp = base[p]
            d = env[bp + p]
            a = abs(d)
            if not np.isfinite(d) or (not (a > thresh) and not (static_pivot > 0.0 and dmax > 0.0)):
                stats[1] = min(pmin, a)
                stats[2] = d
                return p
            if a < pmin:
                pmin = a
            if not (a > thresh):
                d = math.copysign(static_pivot * dmax, d)
                env[bp + p] = d
                replaced += 1
            inv = 1.0 / d
            inv_diag[p] = inv
            for i in range(p + 1, k1):
                bi = base[i]
                l = env[bi + p] * inv
                env[bi + p] = l
                for t in range(urun_ptr[p], urun_ptr[p + 1]):
                    lo = urun_lo[t]
                    oi = np.uint64(bi + lo)      # unsigned: no negative-index test in the loop
                    op = np.uint64(bp + lo)
                    for jj in range(urun_hi[t] - lo):
                        j = np.uint64(jj)
                        env[oi + j] -= l * env[op + j]
        # (b) rows below the block: L entries by a small triangular solve, then the Schur update
        #     of the common outer structure S = struct(k1 - 1) with rank (k1 - k0)
        kl = k1 - 1
        s0 = urun_ptr[kl]
        s1 = urun_ptr[kl + 1]
        r = k1 - k0
        if r == 4:
            b0 = base[k0]
            b1 = base[k0 + 1]
            b2 = base[k0 + 2]
            b3 = base[k0 + 3]
            u01 = env[b0 + k0 + 1]
            u02 = env[b0 + k0 + 2]
            u03 = env[b0 + k0 + 3]
            u12 = env[b1 + k0 + 2]
            u13 = env[b1 + k0 + 3]
            u23 = env[b2 + k0 + 3]
            v0 = inv_diag[k0]
            v1 = inv_diag[k0 + 1]
            v2 = inv_diag[k0 + 2]
            v3 = inv_diag[k0 + 3]
            for s in range(s0, s1):
                i = urun_lo[s]
                while i < urun_hi[s]:
                    two = i + 1 < urun_hi[s]
                    bi = base[i] + k0
                    a0 = env[bi]
                    a1 = env[bi + 1]
                    a2 = env[bi + 2]
                    a3 = env[bi + 3]
                    l0 = a0 * v0
                    l1 = (a1 - l0 * u01) * v1
                    l2 = (a2 - l0 * u02 - l1 * u12) * v2
                    l3 = (a3 - l0 * u03 - l1 * u13 - l2 * u23) * v3
                    env[bi] = l0
                    env[bi + 1] = l1
                    env[bi + 2] = l2
                    env[bi + 3] = l3
                    bi = base[i]
                    if two:                      # two rows at once share the loads of U
                        bj = base[i + 1] + k0
                        a0 = env[bj]
                        a1 = env[bj + 1]
                        a2 = env[bj + 2]
                        a3 = env[bj + 3]
                        m0 = a0 * v0
                        m1 = (a1 - m0 * u01) * v1
                        m2 = (a2 - m0 * u02 - m1 * u12) * v2
                        m3 = (a3 - m0 * u03 - m1 * u13 - m2 * u23) * v3
                        env[bj] = m0
                        env[bj + 1] = m1
                        env[bj + 2] = m2
                        env[bj + 3] = m3
                        bj = base[i + 1]
                        for t in range(s0, s1):
                            lo = urun_lo[t]
                            oi = np.uint64(bi + lo)
                            oj = np.uint64(bj + lo)
                            o0 = np.uint64(b0 + lo)
                            o1 = np.uint64(b1 + lo)
                            o2 = np.uint64(b2 + lo)
                            o3 = np.uint64(b3 + lo)
                            for jj in range(urun_hi[t] - lo):
                                j = np.uint64(jj)
                                x0 = env[o0 + j]
                                x1 = env[o1 + j]
                                x2 = env[o2 + j]
                                x3 = env[o3 + j]
                                env[oi + j] -= l0 * x0 + l1 * x1 + l2 * x2 + l3 * x3
                                env[oj + j] -= m0 * x0 + m1 * x1 + m2 * x2 + m3 * x3
                        i += 2
                    else:
                        for t in range(s0, s1):
                            lo = urun_lo[t]
                            oi = np.uint64(bi + lo)
                            o0 = np.uint64(b0 + lo)
                            o1 = np.uint64(b1 + lo)
                            o2 = np.uint64(b2 + lo)
                            o3 = np.uint64(b3 + lo)
                            for jj in range(urun_hi[t] - lo):
                                j = np.uint64(jj)
                                env[oi + j] -= (l0 * env[o0 + j] + l1 * env[o1 + j] + l2 * env[o2 + j]
                                                + l3 * env[o3 + j])
                        i += 1
        else:
            for s in range(s0, s1):
                for i in range(urun_lo[s], urun_hi[s]):
                    bi = base[i]
                    for p in range(k0, k1):
                        acc = env[bi + p]
                        for q in range(k0, p):
                            acc -= env[bi + q] * env[base[q] + p]
                        env[bi + p] = acc * inv_diag[p]
                    p = k0
                    while p < k1:
                        if k1 - p >= 2:
                            l0 = env[bi + p]
                            l1 = env[bi + p + 1]
                            b0 = base[p]
                            b1 = base[p + 1]
                            for t in range(s0, s1):
                                lo = urun_lo[t]
                                oi = np.uint64(bi + lo)
                                o0 = np.uint64(b0 + lo)
                                o1 = np.uint64(b1 + lo)
                                for jj in range(urun_hi[t] - lo):
                                    j = np.uint64(jj)
                                    env[oi + j] -= l0 * env[o0 + j] + l1 * env[o1 + j]
                            p += 2
                        else:
                            l0 = env[bi + p]
                            b0 = base[p]
                            for t in range(s0, s1):
                                lo = urun_lo[t]
                                oi = np.uint64(bi + lo)
                                o0 = np.uint64(b0 + lo)
                                for jj in range(urun_hi[t] - lo):
                                    j = np.uint64(jj)
                                    env[oi + j] -= l0 * env[o0 + j]
                            p += 1
    if scale != 1.0:
        _unscale_late(n - nlate, scale, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, env, inv_diag)
    stats[1] = pmin
    stats[2] = replaced
    return -1


@register_jitable             # inlined into _factor_kernel (no dispatcher of its own to cache)
def _scale_late(n0, s, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, env):
    """``D A D`` in place, ``D = diag(1, …, 1, s, …, s)`` (``s`` from row ``n0`` on), over the
    structural entries (see :func:`_factor_kernel`, ``nlate``)."""
    n = base.shape[0]
    for i in range(n):
        di = s if i >= n0 else 1.0
        bi = base[i]
        if i >= n0:
            for t in range(lrun_ptr[i], lrun_ptr[i + 1]):
                for j in range(lrun_lo[t], lrun_hi[t]):
                    env[bi + j] *= s * s if j >= n0 else s
            env[bi + i] *= s * s
        for t in range(urun_ptr[i], urun_ptr[i + 1]):
            for j in range(max(urun_lo[t], n0), urun_hi[t]):
                env[bi + j] *= di * s


@register_jitable
def _unscale_late(n0, s, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, env, inv_diag):
    """Factors of ``A`` from those of ``D A D = L U``: ``A = (D⁻¹ L D)(D⁻¹ U D⁻¹)``, i.e.
    ``L_ij·d_j/d_i`` (unit diagonal kept) and ``U_ij/(d_i d_j)`` (see :func:`_factor_kernel`)."""
    n = base.shape[0]
    r = 1.0 / s
    for i in range(n):
        bi = base[i]
        if i >= n0:
            for t in range(lrun_ptr[i], lrun_ptr[i + 1]):
                for j in range(lrun_lo[t], min(lrun_hi[t], n0)):
                    env[bi + j] *= r
            env[bi + i] *= r * r
            inv_diag[i] *= s * s
        di = s if i >= n0 else 1.0
        for t in range(urun_ptr[i], urun_ptr[i + 1]):
            for j in range(max(urun_lo[t], n0), urun_hi[t]):
                env[bi + j] *= 1.0 / (di * s)


@njit(fastmath=_FASTMATH, **KERNEL)
def _solve_kernel(b, perm, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, env,
                  inv_diag, work, out):
    """Solve ``A x = b`` with the factors of ``P A Pᵀ = L U``.

    Parameters
    ----------
    b : float64 (n,)
        Right-hand side (original numbering).
    perm : int64 (n,)
        ``perm[i]`` is the original index of permuted unknown ``i``.
    base : int64 (n,)
    lrun_ptr, lrun_lo, lrun_hi : int64
        Structure of the rows of ``L`` as runs.
    urun_ptr, urun_lo, urun_hi : int64
        Structure of the rows of ``U`` as runs.
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
    for i in range(n):                                   # L y = P b
        bi = base[i]
        acc = work[i]
        for s in range(lrun_ptr[i], lrun_ptr[i + 1]):
            lo = lrun_lo[s]
            m = lrun_hi[s] - lo
            li = env[bi + lo:bi + lo + m]
            y = work[lo:lo + m]
            for j in range(m):
                acc -= li[j] * y[j]
        work[i] = acc
    for i in range(n - 1, -1, -1):                       # U z = y
        bi = base[i]
        acc = work[i]
        for s in range(urun_ptr[i], urun_ptr[i + 1]):
            lo = urun_lo[s]
            m = urun_hi[s] - lo
            ui = env[bi + lo:bi + lo + m]
            z = work[lo:lo + m]
            for j in range(m):
                acc -= ui[j] * z[j]
        work[i] = acc * inv_diag[i]
    for i in range(n):
        out[perm[i]] = work[i]


@register_jitable             # inlined into _refine_kernel
def _residual_kernel(data, data2, coef, indptr, indices, b, x, res):
    """``res = b − A x`` with ``A = data + coef * data2`` (CSR, duplicates summed); returns
    ``‖res‖∞``."""
    worst = 0.0
    for i in range(b.shape[0]):
        acc = b[i]
        for p in range(indptr[i], indptr[i + 1]):
            acc -= (data[p] + coef * data2[p]) * x[indices[p]]
        res[i] = acc
        if not abs(acc) <= worst:
            worst = abs(acc)
    return worst


@njit(**KERNEL)
def _refine_kernel(data, data2, coef, indptr, indices, b, x, perm, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr,
                   urun_lo, urun_hi, env, inv_diag, work, res, corr, basis, hess, rot):
    """Refine ``x ≈ A⁻¹ b`` (``A = data + coef * data2`` on the CSR pattern ``indptr, indices``)
    by GMRES right-preconditioned with the factors of :func:`_factor_kernel` — of ``A``, or of
    ``A + E`` when it replaced pivots (static pivoting) — and return the backward error of the
    result.

    ``E`` has the rank ``k`` of the pivots replaced, so the preconditioned operator is the identity
    plus a rank-``k`` term and GMRES converges in about ``k + 1`` iterations where plain iterative
    refinement (``x += M⁻¹(b − A x)``) may stall: on the off-plane hinge by multipliers
    (``tests/verification/test_joints.py``) it stopped at ω = 4e-10.
    Arrays as in :func:`_solve_kernel`; ``res, corr`` (n,) scratch; ``basis (m + 1, n)``,
    ``hess (m + 1, m)``, ``rot (3, m + 1)`` the Krylov scratch of GMRES(m); at most
    :data:`REFINE_CYCLES` restarts. It stops as soon as the normwise backward error
    ``ω = ‖b − A x‖∞ / (‖A‖∞ ‖x‖∞ + ‖b‖∞)`` is at or below :data:`BACKWARD_ERROR_TOL` (with no
    iteration when ``x`` already is), or when a cycle does not lower it (a cycle that raised it is
    undone). ``x`` (n,) is refined in place.

    Returns
    -------
    float
        ``ω`` of the ``x`` left (``inf`` or ``nan``: no finite solution).
    """
    n = b.shape[0]
    m = hess.shape[1]
    anorm = 0.0
    bnorm = 0.0
    for i in range(n):
        row = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            row += abs(data[p] + coef * data2[p])
        anorm = max(anorm, row)
        bnorm = max(bnorm, abs(b[i]))
    omega = _backward_error(_residual_kernel(data, data2, coef, indptr, indices, b, x, res), anorm, x, bnorm)
    cs, sn, g = rot[0], rot[1], rot[2]
    for _ in range(REFINE_CYCLES):
        if omega <= BACKWARD_ERROR_TOL:
            break
        beta = 0.0
        for i in range(n):
            beta += res[i] * res[i]
        beta = math.sqrt(beta)
        if not (beta > 0.0 and math.isfinite(beta)):
            break
        for i in range(n):
            basis[0, i] = res[i] / beta
        g[:] = 0.0
        g[0] = beta
        # GMRES stops when its residual estimate |g[j+1]| (2-norm ≥ ∞-norm) is well under the bound
        target = 0.1 * BACKWARD_ERROR_TOL * (anorm * _max_abs(x) + bnorm)
        k = 0
        for j in range(m):
            _solve_kernel(basis[j], perm, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, env, inv_diag,
                          work, corr)
            w = basis[j + 1]
            _matvec(data, data2, coef, indptr, indices, corr, w)
            for i in range(j + 1):          # modified Gram–Schmidt
                h = 0.0
                for t in range(n):
                    h += w[t] * basis[i, t]
                hess[i, j] = h
                for t in range(n):
                    w[t] -= h * basis[i, t]
            hn = 0.0
            for t in range(n):
                hn += w[t] * w[t]
            hn = math.sqrt(hn)
            hess[j + 1, j] = hn
            if hn > 0.0:
                for t in range(n):
                    w[t] /= hn
            for i in range(j):              # the previous Givens rotations on the new column
                h = cs[i] * hess[i, j] + sn[i] * hess[i + 1, j]
                hess[i + 1, j] = -sn[i] * hess[i, j] + cs[i] * hess[i + 1, j]
                hess[i, j] = h
            d = math.hypot(hess[j, j], hess[j + 1, j])
            if d > 0.0:
                cs[j] = hess[j, j] / d
                sn[j] = hess[j + 1, j] / d
            else:
                cs[j] = 1.0
                sn[j] = 0.0
            hess[j, j] = d
            hess[j + 1, j] = 0.0
            g[j + 1] = -sn[j] * g[j]
            g[j] = cs[j] * g[j]
            k = j + 1
            if abs(g[j + 1]) <= target or hn == 0.0:
                break
        for i in range(k - 1, -1, -1):      # H y = g (upper triangular), y into g
            h = g[i]
            for t in range(i + 1, k):
                h -= hess[i, t] * g[t]
            g[i] = h / hess[i, i] if hess[i, i] != 0.0 else 0.0
        for t in range(n):                  # x += M⁻¹ V y
            h = 0.0
            for i in range(k):
                h += g[i] * basis[i, t]
            res[t] = h
        _solve_kernel(res, perm, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, env, inv_diag, work,
                      corr)
        for t in range(n):
            x[t] += corr[t]
        new = _backward_error(_residual_kernel(data, data2, coef, indptr, indices, b, x, res), anorm, x, bnorm)
        if not new < omega:
            if not new <= omega:
                for t in range(n):
                    x[t] -= corr[t]
            break
        omega = new
    return omega


@register_jitable
def _matvec(data, data2, coef, indptr, indices, x, out):
    """``out = (data + coef * data2) x`` on the CSR pattern."""
    for i in range(out.shape[0]):
        acc = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            acc += (data[p] + coef * data2[p]) * x[indices[p]]
        out[i] = acc


@register_jitable
def _max_abs(x):
    worst = 0.0
    for i in range(x.shape[0]):
        if not abs(x[i]) <= worst:
            worst = abs(x[i])
    return worst


@register_jitable
def _backward_error(res_norm, anorm, x, bnorm):
    den = anorm * _max_abs(x) + bnorm
    if den == 0.0:
        return 0.0 if res_norm == 0.0 else math.inf
    return res_norm / den


# ---------------------------------------------------------------------------------------------
# The solver
# ---------------------------------------------------------------------------------------------

def refine_scratch(n: int) -> tuple[np.ndarray, ...]:
    """The scratch of :func:`_refine_kernel` for ``n`` unknowns: residual, correction (n,), Krylov
    basis (m + 1, n), Hessenberg matrix (m + 1, m), rotations and right-hand side (3, m + 1)."""
    m = KRYLOV_DIM
    return np.zeros(n), np.zeros(n), np.zeros((m + 1, n)), np.zeros((m + 1, m)), np.zeros((3, m + 1))


def _as_index_array(a, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim != 1 or not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"SkylineLU: {name} must be a 1-D integer array, got shape {a.shape} "
                         f"dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.int64)


class SkylineLU:
    """LU without pivoting of a sparse matrix on a fixed pattern, in envelope (skyline) storage.

    Parameters
    ----------
    n : int
        Number of unknowns.
    indptr : int (n + 1,)
        CSR row pointer of the fixed pattern.
    indices : int (nnz,)
        CSR column indices. The pattern should be structurally symmetric; if it is not, it is
        symmetrized internally (the missing entries are then explicit zeros of the factor).
        Duplicate entries are summed.
    pivot_tol : float, keyword-only
        A pivot ``d`` fails when ``|d| <= pivot_tol * max |diag(A)|`` or ``d`` is not finite.
    ordering : {"auto", "rcm", "natural"}, keyword-only
        ``"auto"`` keeps the cheapest of the given numbering, RCM and the arrowhead orderings.
    late : int, keyword-only
        The last ``late`` unknowns are Lagrange multipliers (a zero diagonal block): every ordering
        keeps them last, each after the unknowns it constrains, and the factorization scales them
        so that their pivots are judged like the others (see :func:`_factor_kernel`).
    static_pivot : float, keyword-only
        ``0`` (default): a failing pivot raises :class:`SingularPivotError`; ``> 0``: it is replaced
        by ``± static_pivot * max |diag(A)|`` (:data:`STATIC_PIVOT` is the usual value) and
        :attr:`replaced_pivots` counts them.

    Attributes
    ----------
    perm : int64 (n,)
        ``perm[i]`` is the original index of the ``i``-th eliminated unknown.
    ordering_name : str
        The ordering kept.
    factor_fma : int
        Multiply–adds of one factorization (``Σ_k |struct(k)|²``).
    nnz_factor : int
        Structural non-zeros of ``L + U``.
    candidates : dict[str, int]
        ``factor_fma`` of every ordering tried.

    Notes
    -----
    Not thread-safe: :meth:`solve` uses an internal scratch vector.
    """

    def __init__(self, n: int, indptr, indices, *, pivot_tol: float = 1e-14, ordering: str = "auto",
                 late: int = 0, static_pivot: float = 0.0):
        n = int(n)
        if n < 1:
            raise ValueError(f"SkylineLU: n must be >= 1, got {n}")
        indptr = _as_index_array(indptr, "indptr")
        indices = _as_index_array(indices, "indices")
        if indptr.shape[0] != n + 1 or indptr[0] != 0 or np.any(np.diff(indptr) < 0) \
                or indptr[-1] != indices.shape[0]:
            raise ValueError(f"SkylineLU: indptr must be non-decreasing, of length n + 1 = {n + 1}, "
                             f"from 0 to len(indices) = {indices.shape[0]}; got length "
                             f"{indptr.shape[0]} from {indptr[0]} to {indptr[-1]}")
        if indices.size and (indices.min() < 0 or indices.max() >= n):
            raise ValueError(f"SkylineLU: column indices must lie in [0, {n}), got "
                             f"[{indices.min()}, {indices.max()}]")
        if ordering not in ("auto", "rcm", "natural"):
            raise ValueError(f"SkylineLU: ordering must be 'auto', 'rcm' or 'natural', got {ordering!r}")
        if not pivot_tol >= 0.0:
            raise ValueError(f"SkylineLU: pivot_tol must be >= 0, got {pivot_tol}")
        if not 0 <= late <= n:
            raise ValueError(f"SkylineLU: late must lie in [0, {n}], got {late}")
        if not 0.0 <= static_pivot < 1.0:
            raise ValueError(f"SkylineLU: static_pivot must lie in [0, 1), got {static_pivot}")
        self.static_pivot = float(static_pivot)
        self.indptr, self.indices = indptr, indices         # the given pattern (refine's residuals)
        self.n = n
        self.nnz = int(indices.shape[0])
        self.pivot_tol = float(pivot_tol)
        self.late = int(late)

        a = sp.csr_matrix((np.ones(self.nnz), indices, indptr), shape=(n, n))
        sym = (abs(a) + abs(a.T) + sp.identity(n, format="csr")).tocsr()
        sym.sum_duplicates()
        sym.sort_indices()
        sym.indptr = sym.indptr.astype(np.int64)
        sym.indices = sym.indices.astype(np.int64)

        best = None
        self.candidates = {}
        for name, perm in _candidate_orderings(sym, ordering):
            if late:
                perm = _late_last(sym, perm, n - late)
            ps = sym[perm][:, perm].tocsr()
            ps.sort_indices()
            structure = _symbolic(ps.indptr.astype(np.int64), ps.indices.astype(np.int64))
            counts = np.diff(structure[2])
            fma = int(np.dot(counts, counts))
            self.candidates[name] = fma
            if best is None or fma < best[0]:
                best = (fma, name, perm, structure)
        self.factor_fma, self.ordering_name, perm, (lptr, lidx, uptr, uidx) = best
        self.perm = np.ascontiguousarray(perm, dtype=np.int64)
        iperm = np.empty(n, np.int64)
        iperm[self.perm] = np.arange(n, dtype=np.int64)
        self.nnz_factor = int(2 * lptr[-1] + n)

        self._lrun = _to_runs(lptr, lidx)
        self._urun = _to_runs(uptr, uidx)
        self._blk_ptr = _blocks(uptr, uidx, _MAX_BLOCK)

        # variable-band row storage: row i holds columns first[i] .. last[i]
        rows = np.arange(n, dtype=np.int64)
        counts_l = np.diff(lptr)
        counts_u = np.diff(uptr)
        self._first = rows.copy()                                   # (n,) first column of row i
        self._first[counts_l > 0] = lidx[lptr[:-1][counts_l > 0]]
        self._last = rows.copy()                                    # (n,) last column of row i
        self._last[counts_u > 0] = uidx[uptr[1:][counts_u > 0] - 1]
        start = np.zeros(n + 1, np.int64)
        np.cumsum(self._last - self._first + 1, out=start[1:])
        self._base = np.ascontiguousarray(start[:-1] - self._first)
        self._env = np.zeros(int(start[-1]), np.float64)

        # scatter map: CSR position -> envelope slot
        csr_rows = np.repeat(rows, np.diff(indptr))
        self._slot = np.ascontiguousarray(self._base[iperm[csr_rows]] + iperm[indices])
        # structural slots: clear the fill before each scatter (all of them if entries repeat)
        structural = np.concatenate((self._base[np.repeat(rows, counts_l)] + lidx,
                                     self._base + rows,
                                     self._base[np.repeat(rows, counts_u)] + uidx))
        self._accumulate = bool(np.unique(self._slot).size < self._slot.size)
        self._zero_slots = np.ascontiguousarray(
            structural if self._accumulate else np.setdiff1d(structural, self._slot), dtype=np.int64)
        self._inv_diag = np.zeros(n, np.float64)
        self._work = np.zeros(n, np.float64)
        self._stats = np.zeros(3, np.float64)
        self._scratch = None                                        # refine's (refine_scratch)
        self._factored = False

    # -- properties -----------------------------------------------------------------------------

    @property
    def bandwidth(self) -> int:
        """Largest half-bandwidth ``max_i max(i - first[i], last[i] - i)`` of the permuted matrix."""
        rows = np.arange(self.n)
        return int(max(np.max(rows - self._first), np.max(self._last - rows)))

    @property
    def profile_size(self) -> int:
        """Entries of the envelope storage (``L`` and ``U`` envelopes plus the diagonal)."""
        return int(self._env.shape[0])

    @property
    def min_pivot_ratio(self) -> float:
        """``min |pivot| / max |diag(A)|`` of the last successful factorization (``nan`` before)."""
        if not self._factored or self._stats[0] == 0.0:
            return float("nan")
        return float(self._stats[1] / self._stats[0])

    @property
    def replaced_pivots(self) -> int:
        """Pivots the last successful factorization replaced (static pivoting); ``-1`` before one."""
        return int(self._stats[2]) if self._factored else -1

    @property
    def negative_pivots(self) -> int:
        """Pivots < 0 of the last successful factorization (for a symmetric matrix, its number of
        negative eigenvalues: Sylvester's law of inertia); ``-1`` before one."""
        return int(np.count_nonzero(self._inv_diag < 0.0)) if self._factored else -1

    # -- numerics -------------------------------------------------------------------------------

    def _writable(self, a: np.ndarray) -> np.ndarray:
        """``a``, or a copy of it when it is read-only (a model's constant mass matrix): numba
        compiles a read-only array as another type, i.e. a second kernel signature. The copy of the
        last read-only array is kept, so a constant matrix is copied once."""
        if a.flags.writeable:
            return a
        cached = getattr(self, "_ro_copy", None)
        if cached is None or cached[0] is not a:
            cached = (a, a.copy())
            self._ro_copy = cached
        return cached[1]

    def factor(self, data, *, mass=None, coef: float = 0.0) -> None:
        """Factor ``A = data + coef * mass`` (CSR values on the fixed pattern).

        Parameters
        ----------
        data : float64 (nnz,)
            Values of ``A`` (or of ``K`` when ``mass`` is given).
        mass : float64 (nnz,), optional, keyword-only
            Values of a second matrix on the same pattern, added with factor ``coef`` during the
            scatter (``K + c M`` of an implicit integrator without a temporary array).
        coef : float, keyword-only

        Raises
        ------
        SingularPivotError
            A pivot is not finite or ``|pivot| <= pivot_tol * max |diag(A)|``.
        """
        data = self._writable(np.ascontiguousarray(data, dtype=np.float64))
        if data.shape != (self.nnz,):
            raise ValueError(f"SkylineLU.factor: data must have shape ({self.nnz},), got {data.shape}")
        if mass is None:
            mass, coef = data, 0.0
        else:
            mass = self._writable(np.ascontiguousarray(mass, dtype=np.float64))
            if mass.shape != (self.nnz,):
                raise ValueError(f"SkylineLU.factor: mass must have shape ({self.nnz},), got {mass.shape}")
        self._factored = False
        step = _factor_kernel(data, mass, float(coef), self._slot, self._accumulate, self._zero_slots,
                              self._base, *self._lrun, *self._urun, self._blk_ptr,
                              self._env, self._inv_diag, self.pivot_tol, self.static_pivot, self._stats,
                              self.late)
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
            Where to write ``x``; may be ``b`` itself. Nothing is allocated when ``out`` is given
            and ``b`` is already a C-contiguous float64 array.

        Returns
        -------
        x : float64 (n,)
            ``out`` when given.
        """
        if not self._factored:
            raise NotFactoredError("SkylineLU.solve: no valid factorization; call factor(data) "
                                   "first (the last factor() may have raised SingularPivotError)")
        b = np.ascontiguousarray(b, dtype=np.float64)
        if b.shape != (self.n,):
            raise ValueError(f"SkylineLU.solve: b must have shape ({self.n},), got {b.shape}")
        if out is None:
            out = np.empty(self.n, np.float64)
        elif not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.shape == (self.n,)
                  and out.flags.c_contiguous and out.flags.writeable):
            raise ValueError(f"SkylineLU.solve: out must be a writable C-contiguous float64 array "
                             f"of shape ({self.n},)")
        _solve_kernel(b, self.perm, self._base, *self._lrun, *self._urun, self._env, self._inv_diag,
                      self._work, out)
        return out

    def refine(self, data, b, x, *, mass=None, coef: float = 0.0) -> float:
        """Refine ``x`` (n,), a solution of ``A x = b`` from :meth:`solve`, in place against
        ``A = data + coef * mass`` — the matrix of the last :meth:`factor` — and return its normwise
        backward error (:func:`_refine_kernel`; trust ``x`` when it is at most
        :data:`BACKWARD_ERROR_TOL`)."""
        if not self._factored:
            raise NotFactoredError("SkylineLU.refine: no valid factorization")
        data = np.ascontiguousarray(data, dtype=np.float64)
        mass, coef = (data, 0.0) if mass is None else (np.ascontiguousarray(mass, dtype=np.float64), coef)
        b = np.ascontiguousarray(b, dtype=np.float64)
        if self._scratch is None:
            self._scratch = refine_scratch(self.n)
        return float(_refine_kernel(data, mass, float(coef), self.indptr, self.indices, b, x, self.perm, self._base,
                                    *self._lrun, *self._urun, self._env, self._inv_diag, self._work,
                                    *self._scratch))

    def __repr__(self) -> str:
        return (f"SkylineLU(n={self.n}, ordering={self.ordering_name!r}, bandwidth={self.bandwidth}, "
                f"profile_size={self.profile_size}, nnz_factor={self.nnz_factor}, "
                f"factor_fma={self.factor_fma})")
