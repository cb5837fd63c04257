"""Shell element (SPEC §2): quadrature and shape functions, tangent = finite difference of the
residual = finite difference of the energy, zero energy and force under rigid motion, exact
membrane patch, Poisson-locking-free bending, constant mass; the assumed strains (issue 16): exactly
the 6 rigid zero-energy modes on flat, cylindrical and spherical elements, the patch test on
non-affine elements, and the membrane weight."""

from math import factorial

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from flexmb_core.kernels.shell import NDOF_NODE, NLOC, const_rows, shell_constants, shell_element, shell_scratch
from flexmb_core.model.shell_geometry import (LOCAL_NODES_3L, MEMBRANE_ALPHA, cubic_triangle, membrane_weight,
                                              shell_element_geometry,
                                              shell_element_mass, shell_rule, triangle_rule)

E, NU, RHO = 2.0e11, 0.3, 7850.0
LAM = E * NU / ((1 + NU) * (1 - 2 * NU))
MU = E / (2 * (1 + NU))


@pytest.mark.parametrize("n", [3, 4, 5])
def test_triangle_rule_exact_to_degree_2n_minus_1(n):
    pts, wts = triangle_rule(n)
    for a in range(2 * n):
        for b in range(2 * n - a):
            exact = factorial(a) * factorial(b) / factorial(a + b + 2)
            assert (wts * pts[:, 0] ** a * pts[:, 1] ** b).sum() == pytest.approx(exact, rel=1e-12, abs=1e-15)


def test_cubic_shape_functions_interpolate_and_sum_to_one():
    for k, l3 in enumerate(LOCAL_NODES_3L):
        phi, _ = cubic_triangle(l3[1] / 3.0, l3[2] / 3.0)
        assert np.allclose(phi, np.eye(10)[k], atol=1e-14)
    rng = np.random.default_rng(3)
    for _ in range(5):
        x1, x2 = rng.dirichlet(np.ones(3))[:2]
        phi, dphi = cubic_triangle(x1, x2)
        assert phi.sum() == pytest.approx(1.0, abs=1e-14)
        assert np.allclose(dphi.sum(axis=0), 0.0, atol=1e-13)
        h = 1e-7
        fd = (cubic_triangle(x1 + h, x2)[0] - cubic_triangle(x1 - h, x2)[0]) / (2 * h)
        assert np.allclose(fd, dphi[:, 0], atol=1e-7)


def _mat(h, x, v0, dphi, gm=None, gs=1.0):
    """The compiled model's material row: λ, μ, h0/2 and the assumed-strain weights γ_m = 1 − s, γ_s."""
    if gm is None:
        gm = 1.0 - membrane_weight(x, v0, 2.0 * h, dphi)
    return np.array([LAM, MU, h, gm, gs])


def _element_nodes(kind, radius=0.5):
    """Nodes and exact unit normals of one element: on a cylinder, on a sphere, or flat (a general
    affine triangle)."""
    uv = LOCAL_NODES_3L[:, 1:] / 3.0
    if kind == "cylinder":
        th = 0.6 * uv[:, 0] + 0.1 * uv[:, 1]
        s = 0.3 * uv[:, 1] + 0.05 * uv[:, 0]
        return (np.column_stack((radius * np.cos(th), radius * np.sin(th), s)),
                np.column_stack((np.cos(th), np.sin(th), np.zeros(10))))
    if kind == "sphere":
        th = 0.5 + 0.4 * uv[:, 0] + 0.1 * uv[:, 1]
        ph = 0.2 * uv[:, 0] + 0.5 * uv[:, 1]
        v0 = np.column_stack((np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)))
        return radius * v0, v0
    x = np.column_stack((0.35 * uv[:, 0] + 0.1 * uv[:, 1], 0.3 * uv[:, 1], np.zeros(10)))
    return x, np.tile([0.0, 0.0, 1.0], (10, 1))


def _curved_element(h=0.02, radius=0.5, kind="cylinder", gm=None, gs=1.0):
    """One element on a cylinder (curved reference, nodal normals exact), or ``kind``."""
    x, v0 = _element_nodes(kind, radius)
    phi, dphi, zeta, wts = shell_rule(4, 3)
    a0inv, w = shell_element_geometry(x, v0, h, phi, dphi, zeta, wts)
    q0 = np.zeros(NLOC)
    for n in range(10):
        q0[NDOF_NODE * n:NDOF_NODE * n + 3] = x[n]
        q0[NDOF_NODE * n + 3:NDOF_NODE * n + 6] = v0[n]
    return q0, (phi, dphi, zeta, a0inv, w, _mat(h, x, v0, dphi, gm, gs)), x


def _frozen(a: np.ndarray) -> np.ndarray:
    b = np.ascontiguousarray(a, dtype=float)
    if b is a:
        b = a.copy()
    b.setflags(write=False)
    return b


def _eval(q, geo, want_k=True):
    sc = shell_scratch()
    dv, dfa, f, bm, cb, _, re, ke = sc
    # the compiled model's geometry arrays are read-only: call the kernel with the same signature
    # (tests/unit/test_signatures.py: one signature per kernel in one process)
    phi, dphi, zeta, a0inv, w, mat = (_frozen(g) for g in geo)
    const = np.zeros((const_rows(w.size, w.size), 9))      # rows for as many in-plane points as points
    assert shell_constants(phi, dphi, zeta, a0inv, w, const) > 0
    u = shell_element(q, phi, dphi, zeta, a0inv, w, mat, _frozen(const), want_k, dv, dfa, f, bm, cb, re, ke)
    return u, re.copy(), ke.copy()


def test_reference_state_is_stress_free():
    q0, geo, _ = _curved_element()
    u, r, _ = _eval(q0, geo)
    assert u < 1e-20 * E * 0.02
    assert np.abs(r).max() < 1e-12 * E * 0.02 ** 2


@pytest.mark.parametrize("kind, gm, gs", [("cylinder", None, 1.0), ("sphere", None, 1.0), ("cylinder", 0.7, 0.0),
                                          ("cylinder", 0.0, 0.0)])
def test_tangent_and_residual_match_finite_differences(kind, gm, gs):
    """The assumed strains (membrane weight from the geometry, or given; the unprojected element
    with both weights 0) keep a pure energy: residual = ∂U/∂q, tangent = ∂r/∂q, symmetric."""
    q0, geo, _ = _curved_element(kind=kind, gm=gm, gs=gs)
    rng = np.random.default_rng(7)
    q = q0 + 0.02 * rng.standard_normal(NLOC)      # large, with strain rates a ≠ 0
    u, r, k = _eval(q, geo)
    assert np.abs(k - k.T).max() == 0.0
    h = 1e-6
    gfd = np.empty(NLOC)
    kfd = np.empty((NLOC, NLOC))
    for j in range(NLOC):
        qp, qm = q.copy(), q.copy()
        qp[j] += h
        qm[j] -= h
        up, rp, _ = _eval(qp, geo, False)
        um, rm, _ = _eval(qm, geo, False)
        gfd[j] = (up - um) / (2 * h)
        kfd[:, j] = (rp - rm) / (2 * h)
    assert np.abs(gfd - r).max() <= 1e-7 * np.abs(r).max()
    assert np.abs(kfd - k).max() <= 1e-7 * np.abs(k).max()


def test_rigid_motion_gives_zero_energy_and_force():
    q0, geo, x = _curved_element()
    rng = np.random.default_rng(11)
    q = q0.copy()
    for n in range(10):                                 # a deformed state, then rotated rigidly
        q[NDOF_NODE * n:NDOF_NODE * n + 6] += 0.01 * rng.standard_normal(6)
        q[NDOF_NODE * n + 6] = 0.05 * rng.standard_normal()
    u_def, r_def, _ = _eval(q, geo, False)
    rot = Rotation.from_rotvec([0.4, -1.3, 2.2]).as_matrix()
    qr, q0r = q.copy(), q0.copy()
    for n in range(10):
        b = NDOF_NODE * n
        for arr, src in ((qr, q), (q0r, q0)):
            arr[b:b + 3] = rot @ src[b:b + 3] + np.array([1.0, -2.0, 0.5])
            arr[b + 3:b + 6] = rot @ src[b + 3:b + 6]
    u0, r0, _ = _eval(q0r, geo, False)
    assert u0 < 1e-18 * E * 0.02
    assert np.abs(r0).max() < 1e-9 * E * 0.02 ** 2
    u_rot, r_rot, _ = _eval(qr, geo, False)
    assert u_rot == pytest.approx(u_def, rel=1e-12)
    for n in range(10):                                 # forces rotate with the body
        b = NDOF_NODE * n
        assert np.allclose(r_rot[b:b + 3], rot @ r_def[b:b + 3], atol=1e-9 * np.abs(r_def).max())
        assert r_rot[b + 6] == pytest.approx(r_def[b + 6], rel=1e-9, abs=1e-9 * np.abs(r_def).max())


def _flat_square_patch(hh):
    """Two-element flat patch [0, 1]² (z = 0, normals +z, half thickness ``hh``) from the mesh generator."""
    from flexmb_core.model.shell_mesh import rectangle
    mesh = rectangle([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], (1, 1), "right")
    phi, dphi, zeta, wts = shell_rule(4, 3)
    return mesh, [shell_element_geometry(mesh.x[t], mesh.normal[t], hh, phi, dphi, zeta, wts) for t in mesh.tri], \
        (phi, dphi, zeta)


def test_membrane_patch_is_exact():
    """Uniform stretch ε in x with free lateral contraction: U = ½ E ε_G² · volume exactly, once the
    lateral and thickness stretches sit at their (uniaxial-stress) minimum."""
    h = 0.01                                  # half thickness: volume 2h
    mesh, geos, (phi, dphi, zeta) = _flat_square_patch(h)
    stretch = 1.001
    eg = 0.5 * (stretch ** 2 - 1.0)
    lat = np.sqrt(1.0 - 2.0 * NU * eg)        # SVK uniaxial stress: E_yy = E_zz = −ν E_xx
    u = 0.0
    for t, (a0inv, w) in zip(mesh.tri, geos):
        q = np.zeros(NLOC)
        for n, node in enumerate(t):
            xn = mesh.x[node]
            q[7 * n:7 * n + 3] = (stretch * xn[0], lat * xn[1], 0.0)
            q[7 * n + 3:7 * n + 6] = (0.0, 0.0, lat)
        u += _eval(q, (phi, dphi, zeta, a0inv, w, _mat(h, mesh.x[t], mesh.normal[t], dphi)), False)[0]
    assert u == pytest.approx(0.5 * E * eg ** 2 * 2 * h, rel=1e-10)


def test_pure_bending_has_plate_stiffness_without_poisson_locking():
    """Cylindrical bending κ about y with free anticlastic curvature and thickness strain:
    minimised over the transverse unknowns, U = ½ D κ² A with D = E h³/(12(1 − ν²)) — the
    full 3D law with the thickness strain rate gives the plate (not the 3D-locked) stiffness."""
    from scipy.optimize import minimize
    h = 0.002
    mesh, geos, (phi, dphi, zeta) = _flat_square_patch(h / 2)
    kappa = 1e-5      # small: the membrane strain ½(κx)² of large deflection stays ≪ κh/2
    nn = mesh.x.shape[0]

    def state(p):
        # p: anticlastic curvature, thickness stretch, strain rate, lateral stretch
        ka, ts, a, ly = p
        q = np.zeros((nn, 7))
        x, y = mesh.x[:, 0] - 0.5, mesh.x[:, 1] - 0.5
        q[:, 0], q[:, 1] = x, ly * y
        q[:, 2] = 0.5 * kappa * x ** 2 + 0.5 * ka * y ** 2
        q[:, 3], q[:, 4], q[:, 5] = -kappa * x, -ka * y, ts
        q[:, 6] = a
        return q

    def energy(p):
        q = state(p)
        return sum(_eval(q[t].ravel(), (phi, dphi, zeta, a0inv, w, _mat(h / 2, mesh.x[t], mesh.normal[t], dphi)),
                         False)[0] for t, (a0inv, w) in zip(mesh.tri, geos))

    res = minimize(energy, [-NU * kappa, 1.0, 0.0, 1.0], method="Nelder-Mead",
                   options={"xatol": 1e-14, "fatol": 1e-22, "maxiter": 4000})
    d_plate = E * h ** 3 / (12 * (1 - NU ** 2))
    u_plate_cyl = 0.5 * d_plate * kappa ** 2 * (1 - NU ** 2)   # anticlastic free: ½ E I κ² per width
    assert res.fun == pytest.approx(u_plate_cyl, rel=2e-3)
    # the same bending with the thickness strain rate held at 0 locks: +9.9 % for ν = 0.3 with the
    # anticlastic curvature free (the thickness strain cannot vary linearly through the thickness)
    locked = minimize(lambda p: energy([p[0], p[1], 0.0, p[2]]), [-NU * kappa, 1.0, 1.0], method="Nelder-Mead",
                      options={"xatol": 1e-14, "fatol": 1e-22, "maxiter": 4000})
    assert locked.fun > 1.08 * res.fun


def test_mass_is_constant_symmetric_positive_and_carries_the_element_mass():
    q0, geo, _ = _curved_element()
    phi, _, zeta, _, _, mat = geo
    phi_m, dphi_m, zeta_m, wts_m = shell_rule(4, 3)
    uv = LOCAL_NODES_3L[:, 1:] / 3.0
    th = 0.6 * uv[:, 0] + 0.1 * uv[:, 1]
    s = 0.3 * uv[:, 1] + 0.05 * uv[:, 0]
    x = np.column_stack((0.5 * np.cos(th), 0.5 * np.sin(th), s))
    v0 = np.column_stack((np.cos(th), np.sin(th), np.zeros(10)))
    _, w = shell_element_geometry(x, v0, mat[2], phi_m, dphi_m, zeta_m, wts_m)
    m = shell_element_mass(phi_m, zeta_m, w, RHO, mat[2])
    assert np.abs(m - m.T).max() == 0.0
    assert np.linalg.eigvalsh(m).min() > 0.0
    trans = np.zeros(NLOC)
    trans[0::NDOF_NODE] = 1.0                           # unit x velocity of every node's Y
    assert trans @ m @ trans == pytest.approx(RHO * w.sum(), rel=1e-12)


def _stiffness_spectrum(kind, gm=None, gs=1.0):
    q0, geo, _ = _curved_element(kind=kind, gm=gm, gs=gs)
    _, _, k = _eval(q0, geo)
    ev = np.linalg.eigvalsh(k)
    return ev / ev.max()


@pytest.mark.parametrize("kind", ["flat", "cylinder", "sphere"])
def test_assumed_strains_leave_only_the_rigid_zero_energy_modes(kind):
    """At the reference the element's stiffness has exactly 6 zero eigenvalues (the rigid motions),
    the 7th well clear of round-off (measured ≥ 3.6e-7 of the largest at h0 = 0.04, R = 0.5)."""
    ev = _stiffness_spectrum(kind)
    assert (np.abs(ev) < 1e-10).sum() == 6, ev[:9]
    assert ev[6] > 1e-8


def test_membrane_projection_on_p1_alone_has_spurious_modes():
    """Why the membrane strain beyond P1 is kept with the weight s > 0: projected on P1 alone (s = 0)
    a cylindrical element has 3 zero-energy modes besides the rigid ones, a flat one 8."""
    assert (np.abs(_stiffness_spectrum("cylinder", gm=1.0)) < 1e-10).sum() == 9
    assert (np.abs(_stiffness_spectrum("flat", gm=1.0)) < 1e-10).sum() == 14


def test_membrane_weight_is_one_when_flat_and_follows_h2_kappa_over_t():
    """s = 1/√(1 + (α h²κ/t)²): 1 on a flat element; on a sphere κ = 1/R."""
    phi, dphi, zeta, wts = shell_rule(4, 3)
    x, v0 = _element_nodes("flat")
    assert membrane_weight(x, v0, 0.01, dphi) == 1.0
    x, v0 = _element_nodes("sphere", radius=2.0)          # κ = 1/2 everywhere
    h = max(np.linalg.norm(x[i] - x[j]) for i, j in ((0, 1), (1, 2), (2, 0)))
    for t in (0.01, 0.1):
        expected = 1.0 / np.sqrt(1.0 + (MEMBRANE_ALPHA * h * h * 0.5 / t) ** 2)
        assert membrane_weight(x, v0, t, dphi) == pytest.approx(expected, rel=1e-3)


def test_patch_of_non_affine_elements_reproduces_a_homogeneous_state():
    """Membrane patch test through the projection: a 3 × 3 mesh of a general quadrilateral (bilinear map:
    elements with curved in-plane edges, interior nodes) under y = F x, G = F e_z with an in-plane stretch
    and shear and the thickness stretch of plane stress (S33 = 0): the energy is ½ S : E times the volume
    and every interior node is in equilibrium (its 7 residuals vanish)."""
    from flexmb_core.model.shell_mesh import rectangle
    h = 0.01
    mesh = rectangle([(0, 0, 0), (1.2, 0.2, 0), (1.0, 1.1, 0), (-0.1, 0.9, 0)], (3, 3), "alternate")
    phi, dphi, zeta, wts = shell_rule(4, 3)
    f2 = np.array([[1.002, 0.0007], [-0.0004, 0.9993]])
    e2 = 0.5 * (f2.T @ f2 - np.eye(2))
    e33 = -LAM * np.trace(e2) / (LAM + 2 * MU)
    fm = np.eye(3)
    fm[:2, :2] = f2
    fm[2, 2] = np.sqrt(1.0 + 2.0 * e33)
    e3 = 0.5 * (fm.T @ fm - np.eye(3))
    s3 = LAM * np.trace(e3) * np.eye(3) + 2 * MU * e3
    assert abs(s3[2, 2]) < 1e-9 * np.abs(s3).max()
    nn = mesh.x.shape[0]
    r = np.zeros((nn, NDOF_NODE))
    u = vol = 0.0
    for t in mesh.tri:
        a0inv, w = shell_element_geometry(mesh.x[t], mesh.normal[t], h, phi, dphi, zeta, wts)
        mat = _mat(h, mesh.x[t], mesh.normal[t], dphi)
        q = np.zeros((10, NDOF_NODE))
        q[:, :3] = mesh.x[t] @ fm.T
        q[:, 3:6] = fm @ np.array([0.0, 0.0, 1.0])
        ue, re, _ = _eval(q.ravel(), (phi, dphi, zeta, a0inv, w, mat), False)
        u += ue
        vol += w.sum()
        r[t] += re.reshape(10, NDOF_NODE)
    assert u == pytest.approx(0.5 * np.sum(s3 * e3) * vol, rel=1e-10)
    boundary = np.unique(np.concatenate(list(mesh.edges.values())))
    inner = np.setdiff1d(np.arange(nn), boundary)
    assert inner.size > 0
    assert np.abs(r[inner]).max() <= 1e-9 * np.abs(r[boundary, :3]).max()
