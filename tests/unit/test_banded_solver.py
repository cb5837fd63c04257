"""SkylineLU (envelope LU without pivoting on a fixed pattern) against scipy's spsolve.

Patterns are shaped like flexmb's tangents: chains of dense 36×36 element blocks (4 nodes of 9
DOFs) that share one node (9 DOFs) with the next element, several chains joined at shared nodes,
and a random DOF numbering so that the ordering has work to do.
"""

import numba
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from flexmb_core.errors import FlexmbError
from flexmb_core.solvers import banded
from flexmb_core.solvers.banded import NotFactoredError, SingularPivotError, SkylineLU

NODE_DOFS = 9
ELEMENT_NODES = 4


# ---------------------------------------------------------------------------------------------
# mechanisms: lists of element node ids
# ---------------------------------------------------------------------------------------------

class _Nodes:
    def __init__(self):
        self.count = 0

    def new(self):
        self.count += 1
        return self.count - 1


def _chain(nodes: _Nodes, start: int, end: int | None, n_el: int) -> list[list[int]]:
    """Elements from node ``start`` to node ``end`` (a new node if None)."""
    elements = []
    cur = start
    for e in range(n_el):
        el = [cur] + [nodes.new() for _ in range(ELEMENT_NODES - 2)]
        el.append(end if (e == n_el - 1 and end is not None) else nodes.new())
        elements.append(el)
        cur = el[-1]
    return elements


def _single_chain(n_el):
    nodes = _Nodes()
    return _chain(nodes, nodes.new(), None, n_el), nodes.count


def _star(n_el):
    """Three chains meeting at one node."""
    nodes = _Nodes()
    hub = nodes.new()
    return sum((_chain(nodes, nodes.new(), hub, n_el) for _ in range(3)), []), nodes.count


def _stewart(leg_el, platform_el):
    """Six legs from their own ground nodes, two per platform vertex; platform edges A-B-C-A."""
    nodes = _Nodes()
    vertex = [nodes.new() for _ in range(3)]
    elements = []
    for leg in range(6):
        elements += _chain(nodes, nodes.new(), vertex[leg // 2], leg_el)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        elements += _chain(nodes, vertex[a], vertex[b], platform_el)
    return elements, nodes.count


MECHANISMS = {
    "chain-225": lambda: _single_chain(8),
    "chain-441": lambda: _single_chain(16),
    "star": lambda: _star(4),
    "stewart": lambda: _stewart(3, 2),
}


class Problem:
    """Pattern + element DOF maps of a mechanism with a random DOF numbering."""

    def __init__(self, name, seed=0):
        elements, n_nodes = MECHANISMS[name]()
        rng = np.random.default_rng(seed)
        self.n = n_nodes * NODE_DOFS
        numbering = rng.permutation(self.n)
        self.edofs = [numbering[(NODE_DOFS * np.asarray(el)[:, None] + np.arange(NODE_DOFS)).ravel()]
                      for el in elements]                                  # each (36,)
        a = self.assemble([np.ones((d.size, d.size)) for d in self.edofs])
        self.indptr, self.indices = a.indptr.astype(np.int64), a.indices.astype(np.int64)

    def assemble(self, blocks) -> sp.csr_matrix:
        rows = np.concatenate([np.repeat(d, d.size) for d in self.edofs])
        cols = np.concatenate([np.tile(d, d.size) for d in self.edofs])
        a = sp.csr_matrix((np.concatenate([b.ravel() for b in blocks]), (rows, cols)),
                          shape=(self.n, self.n))
        a.sum_duplicates()
        a.sort_indices()
        return a

    def values(self, kind, seed=1) -> sp.csr_matrix:
        """CSR matrix on the pattern: 'spd', 'indefinite' (symmetric) or 'nonsymmetric'."""
        rng = np.random.default_rng(seed)
        blocks = []
        for d in self.edofs:
            r = rng.standard_normal((d.size, d.size))
            b = r @ r.T / d.size + 0.1 * np.eye(d.size)
            if kind == "nonsymmetric":
                b += 0.03 * rng.standard_normal(b.shape)      # "slightly": follower loads
            blocks.append(b)
        a = self.assemble(blocks)
        if kind == "indefinite":
            # shift into the middle of the widest gap among the lowest fifth of the spectrum:
            # symmetric indefinite, well conditioned
            lam = np.linalg.eigvalsh(a.toarray())
            low = lam[: self.n // 5]
            k = int(np.argmax(np.diff(low)))
            a = (a - 0.5 * (low[k] + low[k + 1]) * sp.identity(self.n)).tocsr()
            a.sort_indices()
        assert np.array_equal(a.indptr, self.indptr) and np.array_equal(a.indices, self.indices)
        return a


def _rel_err(x, ref):
    return np.linalg.norm(x - ref) / np.linalg.norm(ref)


def _backward_err(a, x, b):
    """Normwise backward error ‖Ax − b‖∞ / (‖A‖∞ ‖x‖∞ + ‖b‖∞)."""
    return np.abs(a @ x - b).max() / (abs(a).sum(axis=1).max() * np.abs(x).max() + np.abs(b).max())


@pytest.fixture(scope="module", params=list(MECHANISMS))
def problem(request):
    p = Problem(request.param)
    p.lu = SkylineLU(p.n, p.indptr, p.indices)
    return p


# ---------------------------------------------------------------------------------------------
# accuracy
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["spd", "indefinite", "nonsymmetric"])
def test_solve_matches_spsolve(problem, kind):
    a = problem.values(kind)
    b = np.random.default_rng(2).standard_normal(problem.n)
    problem.lu.factor(a.data)
    x = problem.lu.solve(b)
    assert _rel_err(x, spsolve(a.tocsc(), b)) < 1e-10
    assert _backward_err(a, x, b) < 1e-12          # no pivoting: some growth, still ~1e4 eps
    if kind == "indefinite":
        assert problem.lu.min_pivot_ratio > 1e-8, "test premise: no tiny pivot"


def test_refactor_with_new_values_on_the_same_pattern(problem):
    lu = problem.lu
    for seed, kind in enumerate(("spd", "nonsymmetric", "indefinite", "spd")):
        a = problem.values(kind, seed=10 + seed)
        b = np.random.default_rng(seed).standard_normal(problem.n)
        lu.factor(a.data)
        assert _rel_err(lu.solve(b), spsolve(a.tocsc(), b)) < 1e-10


def test_factor_of_k_plus_c_m_without_a_temporary(problem):
    k = problem.values("nonsymmetric", seed=3)
    m = problem.values("spd", seed=4)
    c = 0.7
    b = np.random.default_rng(5).standard_normal(problem.n)
    problem.lu.factor(k.data, mass=m.data, coef=c)
    ref = spsolve((k + c * m).tocsc(), b)
    assert _rel_err(problem.lu.solve(b), ref) < 1e-10


def test_solve_into_out_without_allocating_and_in_place(problem):
    a = problem.values("spd")
    lu = problem.lu
    lu.factor(a.data)
    b = np.random.default_rng(6).standard_normal(problem.n)
    ref = spsolve(a.tocsc(), b)
    out = np.empty(problem.n)
    assert lu.solve(b, out=out) is out
    assert _rel_err(out, ref) < 1e-10
    bb = b.copy()
    assert lu.solve(bb, out=bb) is bb                 # out may alias b
    assert _rel_err(bb, ref) < 1e-10


def test_pattern_numbering_is_reordered(problem):
    """The random numbering is expensive; the kept ordering is far cheaper, and a chain gets the
    bandwidth of one element."""
    lu = problem.lu
    assert lu.factor_fma == min(lu.candidates.values())
    assert lu.factor_fma < 0.1 * lu.candidates["natural"]
    if problem.n in (225, 441):                                  # single chains
        assert lu.bandwidth == ELEMENT_NODES * NODE_DOFS - 1
        assert lu.nnz_factor == lu.profile_size                  # the envelope is the fill
    assert lu.nnz_factor <= lu.profile_size


def test_stewart_pattern_numbers_the_platform_vertices_last():
    p = Problem("stewart")
    lu = SkylineLU(p.n, p.indptr, p.indices)
    assert lu.ordering_name.startswith("arrowhead")
    assert lu.factor_fma < lu.candidates["rcm"]
    n_vertex_dofs = 3 * NODE_DOFS                    # the only DOFs of degree 9 + 4 * 27
    deg = np.diff(p.indptr)
    assert np.all(deg[lu.perm[-n_vertex_dofs:]] == NODE_DOFS + 4 * 27)


def test_rcm_starts_from_a_peripheral_vertex_on_a_chain():
    """scipy's RCM starts at a minimum-degree vertex, which on a chain may be mid-chain and then
    doubles the bandwidth; the pseudo-peripheral start never does."""
    for seed in range(4):
        p = Problem("chain-441", seed=seed)
        lu = SkylineLU(p.n, p.indptr, p.indices, ordering="rcm")
        assert lu.bandwidth == ELEMENT_NODES * NODE_DOFS - 1


# ---------------------------------------------------------------------------------------------
# failures
# ---------------------------------------------------------------------------------------------

def test_zero_row_raises_singular_pivot_error_and_blocks_solve():
    p = Problem("star")
    lu = SkylineLU(p.n, p.indptr, p.indices)
    a = p.values("spd")
    dead = 17
    rows = np.repeat(np.arange(p.n), np.diff(p.indptr))
    data = a.data.copy()
    data[(rows == dead) | (p.indices == dead)] = 0.0
    with pytest.raises(SingularPivotError) as info:
        lu.factor(data)
    err = info.value
    assert isinstance(err, FlexmbError) and isinstance(err, RuntimeError)
    assert err.row == dead and err.pivot == 0.0
    assert err.threshold == pytest.approx(1e-14 * np.abs(data[rows == p.indices]).max())
    assert f"matrix row {dead}" in str(err) and "too small" in str(err) and "splu" in str(err)
    with pytest.raises(NotFactoredError, match="call factor"):
        lu.solve(np.ones(p.n))
    lu.factor(a.data)                                   # recovers on the next good matrix
    b = np.ones(p.n)
    assert _rel_err(lu.solve(b), spsolve(a.tocsc(), b)) < 1e-10


def test_numerically_singular_pivot_is_detected():
    """[[1, 1], [1, 1]] is structurally fine, its second pivot is exactly 0."""
    lu = SkylineLU(2, np.array([0, 2, 4]), np.array([0, 1, 0, 1]))
    with pytest.raises(SingularPivotError) as info:
        lu.factor(np.array([1.0, 1.0, 1.0, 1.0]))
    assert info.value.pivot == 0.0
    assert info.value.threshold == pytest.approx(1e-14)
    # a pivot just above the relative threshold passes, just below fails
    lu.factor(np.array([1.0, 1.0, 1.0, 1.0 + 1e-12]))
    assert lu.min_pivot_ratio == pytest.approx(1e-12, rel=1e-3)
    with pytest.raises(SingularPivotError):
        lu.factor(np.array([1.0, 1.0, 1.0, 1.0 + 1e-15]))


def test_non_finite_value_raises():
    p = Problem("chain-225")
    lu = SkylineLU(p.n, p.indptr, p.indices)
    a = p.values("spd")
    for bad in (np.nan, np.inf):
        data = a.data.copy()
        data[len(data) // 3] = bad                      # an off-diagonal entry
        with pytest.raises(SingularPivotError, match="not finite"):
            lu.factor(data)
    lu.factor(a.data)
    b = np.ones(p.n)
    assert _rel_err(lu.solve(b), spsolve(a.tocsc(), b)) < 1e-10


@pytest.mark.parametrize("args, message", [
    ((3, [0, 1, 2], [0, 1]), "indptr must be non-decreasing, of length n \\+ 1 = 4"),
    ((2, [0, 1, 2], [0, 2]), "column indices must lie in \\[0, 2\\), got \\[0, 2\\]"),
    ((2, [0, 1, 2], [0.0, 1.0]), "indices must be a 1-D integer array"),
    ((0, [0], []), "n must be >= 1, got 0"),
])
def test_bad_pattern_is_rejected_with_a_message(args, message):
    with pytest.raises(ValueError, match=message):
        SkylineLU(*args)


def test_bad_values_are_rejected_with_a_message():
    lu = SkylineLU(2, np.array([0, 2, 4]), np.array([0, 1, 0, 1]))
    with pytest.raises(ValueError, match=r"data must have shape \(4,\), got \(3,\)"):
        lu.factor(np.ones(3))
    with pytest.raises(ValueError, match=r"mass must have shape \(4,\), got \(5,\)"):
        lu.factor(np.ones(4), mass=np.ones(5), coef=1.0)
    lu.factor(np.array([2.0, 1.0, 1.0, 2.0]))
    with pytest.raises(ValueError, match=r"b must have shape \(2,\), got \(3,\)"):
        lu.solve(np.ones(3))
    with pytest.raises(ValueError, match="out must be a writable C-contiguous float64 array"):
        lu.solve(np.ones(2), out=np.ones(2, dtype=np.float32))


# ---------------------------------------------------------------------------------------------
# patterns outside the main use case
# ---------------------------------------------------------------------------------------------

def test_unsymmetric_pattern_and_duplicate_entries():
    """A pattern that is not structurally symmetric is symmetrized; repeated entries add up."""
    rng = np.random.default_rng(3)
    n = 40
    dense = np.where(rng.random((n, n)) < 0.15, rng.standard_normal((n, n)), 0.0)
    dense += n * np.eye(n)                                         # diagonally dominant
    a = sp.csr_matrix(dense)
    lu = SkylineLU(n, a.indptr, a.indices)
    b = rng.standard_normal(n)
    lu.factor(a.data)
    assert _rel_err(lu.solve(b), np.linalg.solve(dense, b)) < 1e-12
    # the same matrix with every entry split in two halves
    rows = np.repeat(np.arange(n), np.diff(a.indptr))
    order = np.argsort(np.r_[rows, rows], kind="stable")
    cols = np.r_[a.indices, a.indices][order]
    ptr = np.r_[0, np.cumsum(2 * np.diff(a.indptr))]
    lu2 = SkylineLU(n, ptr, cols)
    lu2.factor(np.r_[0.5 * a.data, 0.5 * a.data][order])
    assert _rel_err(lu2.solve(b), np.linalg.solve(dense, b)) < 1e-12


def test_one_unknown():
    lu = SkylineLU(1, np.array([0, 1]), np.array([0]))
    lu.factor(np.array([4.0]))
    assert lu.solve(np.array([2.0]))[0] == 0.5
    assert lu.bandwidth == 0 and lu.profile_size == 1


# ---------------------------------------------------------------------------------------------
# Lagrange multipliers (a zero diagonal block, eliminated last and scaled)
# ---------------------------------------------------------------------------------------------

def _kkt(p: Problem, m: int = 6, stiffness: float = 2e9, seed: int = 3) -> sp.csr_matrix:
    """``[K Gᵀ; G 0]``: K the SPD problem scaled to steel-like stiffness, G ``m`` dense-ish rows of
    O(1) coefficients, each on the DOFs of one element (as rigid corners and ties are)."""
    rng = np.random.default_rng(seed)
    k = stiffness * p.values("spd")
    g = np.zeros((m, p.n))
    for i in range(m):
        d = p.edofs[(7 * i) % len(p.edofs)][:12]
        g[i, d] = rng.standard_normal(d.size)
    a = sp.bmat([[k, sp.csr_matrix(g).T], [sp.csr_matrix(g), None]]).tocsr()
    a.sort_indices()
    return a


def test_multipliers_last_and_scaled_solve_a_saddle_point_system():
    """Without ``late`` a multiplier's zero diagonal is a pivot (or its Schur complement is
    ~1/stiffness: refused as near-singular); with it the factorization keeps them last, its
    pivots are judged like K's, and the solution is the direct solver's."""
    a = _kkt(Problem("stewart"))
    n = a.shape[0]
    b = np.random.default_rng(4).standard_normal(n)
    ref = spsolve(a.tocsc(), b)
    lu = SkylineLU(n, a.indptr, a.indices, late=6)
    assert set(lu.perm[-6:]) == set(range(n - 6, n))
    lu.factor(a.data)
    x = lu.solve(b)
    assert _rel_err(x, ref) < 1e-9
    assert _backward_err(a, x, b) < 1e-14
    assert lu.min_pivot_ratio > 1e-8, lu.min_pivot_ratio
    assert lu.negative_pivots == 6             # inertia of [K Gᵀ; G 0], K SPD: m negative
    plain = SkylineLU(n, a.indptr, a.indices)
    try:
        plain.factor(a.data)
    except SingularPivotError:
        return
    assert plain.min_pivot_ratio < 1e-10


# ---------------------------------------------------------------------------------------------
# compilation
# ---------------------------------------------------------------------------------------------

def test_each_kernel_compiles_one_signature():
    """int32 patterns, float lists and views in, and still one specialization per kernel."""
    p = Problem("stewart")
    lu = SkylineLU(p.n, p.indptr.astype(np.int32), p.indices.astype(np.int32))
    a = p.values("nonsymmetric")
    lu.factor(list(a.data))
    lu.factor(a.data.astype(np.float32), mass=list(a.data), coef=2)
    lu.solve(np.ones(2 * p.n)[::2])
    lu.solve(np.ones(p.n, dtype=np.float32), out=np.empty(p.n))
    SkylineLU(p.n, p.indptr, p.indices, ordering="natural").factor(a.data)
    kkt = _kkt(Problem("stewart"))
    SkylineLU(kkt.shape[0], kkt.indptr, kkt.indices, late=6).factor(kkt.data)
    pivoting = SkylineLU(p.n, p.indptr.astype(np.int32), p.indices, static_pivot=banded.STATIC_PIVOT)
    pivoting.factor(a.data)
    pivoting.refine(list(a.data), np.ones(p.n, dtype=np.float32), pivoting.solve(np.ones(p.n)))
    kernels = {name: obj for name, obj in vars(banded).items()
               if isinstance(obj, numba.core.registry.CPUDispatcher)}
    assert len(kernels) == 7, sorted(kernels)
    for name, disp in kernels.items():
        assert len(disp.signatures) == 1, \
            f"{name} compiled {len(disp.signatures)} signatures: {disp.signatures}"
        assert disp._cache.__class__.__name__ != "NullCache", f"{name} lacks cache=True"


# ---------------------------------------------------------------------------------------------
# static pivoting and refinement (the Newton steps' linear solves)
# ---------------------------------------------------------------------------------------------

def _saddle():
    """[[0, 1, 0], [1, 2, 1], [0, 1, 3]]: non-singular (det = −3) with a zero first pivot — the
    zero leading minor a multiplier row or a free spin gives an LU without pivoting."""
    dense = np.array([[0.0, 1.0, 0.0], [1.0, 2.0, 1.0], [0.0, 1.0, 3.0]])
    a = sp.csr_matrix(dense + 1e-300 * np.eye(3))          # keep the zero diagonal entry stored
    a.data[a.data == 1e-300] = 0.0
    return dense, a


def test_static_pivoting_replaces_a_zero_pivot_and_refinement_recovers_the_solution():
    dense, a = _saddle()
    lu = SkylineLU(3, a.indptr, a.indices, ordering="natural", static_pivot=banded.STATIC_PIVOT)
    lu.factor(a.data)
    assert lu.replaced_pivots == 1
    b = np.array([1.0, 2.0, 3.0])
    x = lu.solve(b)
    exact = np.linalg.solve(dense, b)
    assert _rel_err(x, exact) > 1e-9                       # the factors are a nearby matrix's (error ~ √ε)
    omega = lu.refine(a.data, b, x)
    assert omega <= banded.BACKWARD_ERROR_TOL
    assert _rel_err(x, exact) < 1e-14


def test_refinement_reports_a_singular_matrix():
    """[[1, 1], [1, 1]]: the second pivot is exactly zero and no x solves A x = (1, 2)."""
    lu = SkylineLU(2, np.array([0, 2, 4]), np.array([0, 1, 0, 1]), static_pivot=banded.STATIC_PIVOT)
    data = np.array([1.0, 1.0, 1.0, 1.0])
    lu.factor(data)
    assert lu.replaced_pivots == 1
    b = np.array([1.0, 2.0])
    x = lu.solve(b)
    # x solves a matrix within √ε of A (|x| ~ 1/√ε): its backward error stays far above the bound
    assert lu.refine(data, b, x) > 100 * banded.BACKWARD_ERROR_TOL


def test_fixed_pattern_solver_refines_suspect_factors_and_refuses_singular_ones():
    from flexmb_core.solvers.linear import FixedPatternSolver, SingularMatrixError

    dense, a = _saddle()

    class _Pattern:                                        # the model attributes the solver reads
        nsys, nnz, n_multipliers = 3, a.nnz, 0
        indptr, indices = a.indptr.astype(np.int64), a.indices.astype(np.int64)

    solver = FixedPatternSolver(_Pattern())
    solver.factor(a.data.copy())
    b = np.array([1.0, 2.0, 3.0])
    assert _rel_err(solver.solve(b), np.linalg.solve(dense, b)) < 1e-14
    assert solver.refined == 1
    singular = np.array([1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0])     # rows 0 and 1 both (1, 1, 0): rank 2
    solver.factor(singular)
    with pytest.raises(SingularMatrixError, match=r"singular matrix: backward error .* after refinement, above 1e-11"):
        solver.solve(b)
