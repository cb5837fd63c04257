"""Element kernels: tangent = finite difference of the residual, residual = gradient of the
energy, zero energy and force under rigid motion, actuators stress-free at the commanded length."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from builders import build, cantilever
from flexmb_core.kernels.frame3d import frame_element
from flexmb_core.kernels.truss import truss_element
from flexmb_core.model.assembly import assemble, update_load_scales


def _frame(x, v, g, e, mat, lam, lam_rate, c_v, want_k, want_dlam, sc, re, ke):
    """One frame element through the kernel, with the workspace scratch ``sc`` (re, ke given)."""
    d_, fp, fd, ep, ed, bm, bd, gb, gd, _, _, _, _, kn = sc
    return frame_element(x, v, g.dax[e], g.dsec[e], g.w[e], g.nsec, mat, lam, lam_rate, c_v, want_k, want_dlam,
                         d_, fp, fd, ep, ed, bm, bd, gb, gd, re, ke, kn)


def _mixed_scene():
    """Frames (orders 1–4, straight and curved), a frame actuator, a truss, a bar actuator and
    both kinds of moment loads: every kernel in one model."""
    d = {
        "name": "mixed",
        "materials": {"steel": {"E": 2.0e11, "nu": 0.3, "rho": 7850.0},
                      "soft": {"E": 1.0e7, "nu": 0.45, "rho": 1100.0}},
        "sections": {"rect": {"shape": "rectangle", "width": 0.02, "height": 0.03},
                     "rod": {"shape": "circle", "radius": 0.01},
                     "pipe": {"shape": "tube", "outer_radius": 0.015, "thickness": 0.003}},
        "nodes": {"a": [0, 0, 0], "b": [1, 0, 0], "c": [1, 1, 0.2], "d": [0, 1, 0.5], "e": [2, 0.5, 0],
                  "f": [1.5, -0.8, 0.3]},
        "members": {
            "m1": {"kind": "frame", "from": "a", "to": "b", "elements": 2, "order": 3, "material": "steel",
                   "section": "rect"},
            "m2": {"kind": "frame", "from": "b", "to": "c", "elements": 1, "order": 4, "material": "soft",
                   "section": "rod", "arc": {"center": [0.5, 0.5, 0.1]}},
            "m3": {"kind": "frame", "from": "c", "to": "d", "elements": 2, "order": 1, "material": "steel",
                   "section": "pipe"},
            "m4": {"kind": "frame", "from": "d", "to": "a", "elements": 1, "order": 2, "material": "steel",
                   "section": "rect", "up": [1, 0, 0]},
            "act1": {"kind": "actuator", "from": "b", "to": "e", "elements": 2, "order": 3, "material": "steel",
                     "section": "pipe", "actuator": {"variant": "frame"}},
            "act2": {"kind": "actuator", "from": "e", "to": "f", "material": "steel", "section": "rod",
                     "actuator": {"variant": "bar"}},
            "t1": {"kind": "truss", "from": "f", "to": "a", "elements": 3, "material": "soft", "section": "rod"},
        },
        "supports": [{"node": "a", "type": "ball"}],
        "loads": {"moments": {
            "fm": {"node": "d", "member": "m3", "moment": [3.0, -2.0, 5.0], "follower": True},
            "cm": {"node": "c", "member": "m2", "moment": [0.0, 4.0, 1.0]}}},
        "solver": {"analysis": "static"},
    }
    return build(d)


@pytest.fixture(scope="module")
def mixed():
    model, sim = _mixed_scene()
    update_load_scales(model, sim.ws, 0.0)
    return model, sim


def _perturbed(model, scale, seed=1):
    rng = np.random.default_rng(seed)
    return model.q0 + scale * rng.standard_normal(model.ndof)


def test_global_tangent_matches_finite_difference(mixed):
    model, sim = mixed
    ws = sim.ws
    lam = np.array([1.15, 0.9])
    q = _perturbed(model, 0.03)
    assemble(model, ws, q, lam, True)
    import scipy.sparse as sp
    k = sp.csr_matrix((ws.kdata.copy(), model.indices, model.indptr), shape=(model.nfree,) * 2).toarray()
    free = model.free
    h = 1e-6
    kfd = np.zeros_like(k)
    for j, dof in enumerate(free):
        qp, qm = q.copy(), q.copy()
        qp[dof] += h
        qm[dof] -= h
        assemble(model, ws, qp, lam, False)
        rp = ws.r[free].copy()
        assemble(model, ws, qm, lam, False)
        kfd[:, j] = (rp - ws.r[free]) / (2 * h)
    err = np.abs(k - kfd).max() / np.abs(k).max()
    assert err < 1e-7, f"tangent differs from the finite difference of the residual by {err:.2e}"
    # Follower moments make it non-symmetric; everything else is symmetric.
    assert np.abs(k - k.T).max() / np.abs(k).max() > 1e-12


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("curved", [False, True])
def test_frame_element_tangent_and_energy_gradient(order, curved):
    d = cantilever(elements=1, order=order, E=1e8, nu=0.3, arc_center=(0.0, 2.0, 0.0) if curved else None,
                   tip=[np.sin(0.4) * 2.0, 2.0 - np.cos(0.4) * 2.0, 0.0] if curved else None)
    model, sim = build(d)
    g = model.frame_groups[0]
    sc = sim.ws.frame_scratch[0]
    re, ke = sc[11], sc[12]
    rng = np.random.default_rng(order)
    qe = model.q0[g.edofs[0]] + 0.05 * rng.standard_normal(g.edofs.shape[1])
    for lam in (1.0, 1.2):
        def ev(x):
            r = np.zeros_like(re)
            k = np.zeros_like(ke)
            u, dl, _ = _frame(x, 0 * x, g, 0, g.mat[0], lam, 0.0, 0.0, True, True, sc, r, k)
            return u, dl, r, k
        u, dl, r, k = ev(qe)
        h = 1e-6
        gfd = np.zeros_like(r)
        kfd = np.zeros_like(k)
        for j in range(qe.size):
            e = np.zeros_like(qe)
            e[j] = h
            up, _, rp, _ = ev(qe + e)
            um, _, rm, _ = ev(qe - e)
            gfd[j] = (up - um) / (2 * h)
            kfd[:, j] = (rp - rm) / (2 * h)
        assert np.abs(r - gfd).max() <= 1e-7 * np.abs(r).max()
        assert np.abs(k - kfd).max() <= 1e-7 * np.abs(k).max()
        assert np.array_equal(k, k.T)
        # dU/dλ at fixed q against a central difference in λ
        def energy_at(l):
            return _frame(qe, 0 * qe, g, 0, g.mat[0], l, 0.0, 0.0, False, False, sc, np.zeros_like(re),
                          np.zeros_like(ke))[0]
        dfd = (energy_at(lam + 1e-6) - energy_at(lam - 1e-6)) / 2e-6
        assert dl == pytest.approx(dfd, rel=1e-6)


def _rigidly_moved(model, rot, shift):
    """Apply x ↦ R x + c to positions and v ↦ R v to vectors of the whole model."""
    q = model.q0.copy()
    pos = np.zeros(model.ndof, dtype=bool)
    pos[model.node_ydofs.ravel()] = True
    q3 = q.reshape(-1, 3)
    mask3 = pos.reshape(-1, 3)[:, 0]
    q3[:] = q3 @ rot.T
    q3[mask3] += shift
    return q


def test_rigid_motion_is_stress_free(mixed):
    model, sim = mixed
    ws = sim.ws
    rot = Rotation.from_rotvec([0.7, -1.9, 2.4]).as_matrix()
    q = _rigidly_moved(model, rot, np.array([3.0, -1.0, 2.0]))
    lam = np.ones(2)
    # energy and internal force of the elements alone (loads excluded)
    ws.follower_scale[:] = 0.0
    ws.cons_scale[:] = 0.0
    u = assemble(model, ws, q, lam, False)
    # Scale: the force of a unit strain in the stiffest member (E·A ≈ 1e8 N here).
    force_scale = max(g.mat[:, 0].max() * g.w.sum(axis=1).max() for g in model.frame_groups)
    assert abs(u) < 1e-24 * force_scale
    assert np.abs(ws.r).max() < 1e-12 * force_scale, f"max rigid-motion force {np.abs(ws.r).max():.2e} N"
    update_load_scales(model, ws, 0.0)


def test_actuators_stress_free_at_commanded_length(mixed):
    """Stretch each actuator's axis uniformly to L_cmd = λ·L0 with everything else fixed: zero
    energy and zero force in the actuator elements."""
    model, sim = mixed
    ws = sim.ws
    lam = np.array([1.25, 0.8])
    for ia, name in enumerate(model.actuators.names):
        info = model.member(name)
        q = model.q0.copy()
        x0 = model.q0[info.ydofs[0]]
        for k in range(info.ydofs.shape[0]):
            q[info.ydofs[k]] = x0 + lam[ia] * (model.q0[info.ydofs[k]] - x0)
        g_ids = [(gi, g) for gi, g in enumerate(model.frame_groups) if np.any(g.act == ia)]
        if g_ids:
            gi, g = g_ids[0]
            sc = ws.frame_scratch[gi]
            re, ke = sc[11], sc[12]
            for e in np.nonzero(g.act == ia)[0]:
                u, _, _ = _frame(q[g.edofs[e]], 0 * q[g.edofs[e]], g, e, g.mat[e], lam[ia], 0.0, 0.0, False,
                                 False, sc, re, ke)
                assert abs(u) < 1e-20
                assert np.abs(re).max() < 1e-6
        else:
            t = model.truss
            for e in np.nonzero(t.act == ia)[0]:
                re = np.zeros(6)
                u, _, _ = truss_element(q[t.edofs[e]], np.zeros(6), t.l0[e], t.ea[e], 0.0, lam[ia], 0.0, 0.0,
                                        False, re, np.zeros((6, 6)))
                assert abs(u) < 1e-20
                assert np.abs(re).max() < 1e-6


def _truss(x, v, lam, want_k, re, ke, tau=0.0, lam_rate=0.0, c_v=0.0):
    return truss_element(x, v, 1.1, 3.0e6, tau, lam, lam_rate, c_v, want_k, re, ke)


def test_truss_tangent_and_actuator_derivative():
    x = np.array([0.1, -0.2, 0.3, 1.2, 0.4, -0.1])
    v0 = np.zeros(6)
    for lam in (1.0, 0.7, 1.4):
        re = np.zeros(6)
        ke = np.zeros((6, 6))
        u, dl, _ = _truss(x, v0, lam, True, re, ke)
        h = 1e-7
        kfd = np.zeros((6, 6))
        gfd = np.zeros(6)
        for j in range(6):
            e = np.zeros(6)
            e[j] = h
            rp, rm = np.zeros(6), np.zeros(6)
            up, _, _ = _truss(x + e, v0, lam, False, rp, ke * 0)
            um, _, _ = _truss(x - e, v0, lam, False, rm, ke * 0)
            kfd[:, j] = (rp - rm) / (2 * h)
            gfd[j] = (up - um) / (2 * h)
        re2 = np.zeros(6)
        _truss(x, v0, lam, True, re2, ke)
        assert np.allclose(re2, gfd, rtol=1e-6, atol=1e-6 * np.abs(re2).max())
        assert np.allclose(ke, kfd, rtol=1e-6, atol=1e-6 * np.abs(ke).max())
        up, _, _ = _truss(x, v0, lam + 1e-7, False, re, ke)
        um, _, _ = _truss(x, v0, lam - 1e-7, False, re, ke)
        assert dl == pytest.approx((up - um) / 2e-7, rel=1e-6)


def test_strain_energy_is_frame_invariant(mixed):
    """Same deformation seen from a rotated frame: same energy, rotated forces."""
    model, sim = mixed
    ws = sim.ws
    ws.follower_scale[:] = 0.0
    ws.cons_scale[:] = 0.0
    lam = np.array([1.1, 0.95])
    q = _perturbed(model, 0.02, seed=9)
    rot = Rotation.from_rotvec([-0.3, 0.8, 1.1]).as_matrix()
    u1 = assemble(model, ws, q, lam, False)
    r1 = ws.r.copy()
    q2 = (q.reshape(-1, 3) @ rot.T).ravel()
    u2 = assemble(model, ws, q2, lam, False)
    assert u2 == pytest.approx(u1, rel=1e-10)
    assert np.allclose(ws.r.reshape(-1, 3), r1.reshape(-1, 3) @ rot.T, atol=1e-8 * np.abs(r1).max())
    update_load_scales(model, ws, 0.0)


# -- Kelvin–Voigt material damping ------------------------------------------------------------------
def _fd(f, x, h):
    """Central difference of a vector- or scalar-valued f at x, columns per component of x."""
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h
        cols.append((np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * h))
    return np.array(cols).T


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("curved", [False, True])
def test_damped_frame_element_derivatives(order, curved):
    """With τ > 0: the viscous force is ∂D/∂v (D = half the dissipated power), the tangent is
    ∂r/∂q + c_v ∂r/∂v, the force conjugate to λ is ∂U/∂λ + ∂D/∂λ̇, and the dissipation is ≥ 0."""
    d = cantilever(elements=1, order=order, E=1e8, nu=0.3, arc_center=(0.0, 2.0, 0.0) if curved else None,
                   tip=[np.sin(0.4) * 2.0, 2.0 - np.cos(0.4) * 2.0, 0.0] if curved else None)
    model, sim = build(d)
    g = model.frame_groups[0]
    sc = sim.ws.frame_scratch[0]
    nloc = g.edofs.shape[1]
    rng = np.random.default_rng(10 + order)
    qe = model.q0[g.edofs[0]] + 0.05 * rng.standard_normal(nloc)
    ve = rng.standard_normal(nloc)
    mat = g.mat[0].copy()
    mat[6] = 0.03                       # τ (s): viscous stresses comparable with the elastic ones
    mat.setflags(write=False)           # as the model's (frozen) arrays: the same compiled signature

    def ev(x, v, lam, lrate, c_v=0.0, want_k=False):
        r, k = np.zeros(nloc), np.zeros((nloc, nloc))
        u, dl, p = _frame(x, v, g, 0, mat, lam, lrate, c_v, want_k, True, sc, r, k)
        return u, dl, p, r, k

    for lam, lrate in ((1.0, 0.0), (1.2, 0.7)):
        u, dl, p, r, k0 = ev(qe, ve, lam, lrate, 0.0, True)
        assert p > 0.0
        _, _, p0, r_el, _ = ev(qe, 0 * ve, lam, 0.0)
        assert p0 == 0.0
        # viscous force = ∂D/∂v, D = p/2
        gv = _fd(lambda v: ev(qe, v, lam, lrate)[2] / 2, ve, 1e-6)
        assert np.abs((r - r_el) - gv).max() <= 1e-7 * np.abs(r - r_el).max()
        # tangent at fixed v, and its c_v part = ∂r/∂v
        kq = _fd(lambda x: ev(x, ve, lam, lrate)[3], qe, 1e-6)
        assert np.abs(k0 - kq).max() <= 1e-7 * np.abs(k0).max()
        k1 = ev(qe, ve, lam, lrate, 250.0, True)[4]
        kv = _fd(lambda v: ev(qe, v, lam, lrate)[3], ve, 1e-6)
        assert np.abs((k1 - k0) / 250.0 - kv).max() <= 1e-7 * np.abs(kv).max()
        assert np.abs(k0 - k0.T).max() > 1e-9 * np.abs(k0).max()     # damping makes it non-symmetric
        # conjugate force of λ: ∂U/∂λ (fixed q) + ∂D/∂λ̇ (fixed q, v)
        du = (ev(qe, ve, lam + 1e-6, lrate)[0] - ev(qe, ve, lam - 1e-6, lrate)[0]) / 2e-6
        dd = (ev(qe, ve, lam, lrate + 1e-6)[2] - ev(qe, ve, lam, lrate - 1e-6)[2]) / 4e-6
        assert dl == pytest.approx(du + dd, rel=1e-6)


def test_damped_truss_derivatives():
    x = np.array([0.1, -0.2, 0.3, 1.2, 0.4, -0.1])
    v = np.array([0.3, -1.1, 0.4, -0.2, 0.8, 0.5])
    tau = 0.02
    for lam, lrate in ((1.0, 0.0), (0.8, -0.4), (1.3, 0.9)):
        def ev(x_, v_, lam_=lam, lr=lrate, c_v=0.0):
            re, ke = np.zeros(6), np.zeros((6, 6))
            u, dl, p = _truss(x_, v_, lam_, True, re, ke, tau, lr, c_v)
            return u, dl, p, re, ke
        u, dl, p, r, k0 = ev(x, v)
        assert p > 0.0
        r_el = ev(x, 0 * v, lr=0.0)[3]
        assert np.allclose(r - r_el, _fd(lambda w: ev(x, w)[2] / 2, v, 1e-6), rtol=1e-6, atol=1e-8 * np.abs(r).max())
        assert np.allclose(k0, _fd(lambda y: ev(y, v)[3], x, 1e-7), rtol=1e-6, atol=1e-7 * np.abs(k0).max())
        k1 = ev(x, v, c_v=100.0)[4]
        assert np.allclose((k1 - k0) / 100.0, _fd(lambda w: ev(x, w)[3], v, 1e-6), rtol=1e-6,
                           atol=1e-7 * np.abs(k1 - k0).max() / 100.0)
        du = (ev(x, v, lam + 1e-7)[0] - ev(x, v, lam - 1e-7)[0]) / 2e-7
        dd = (ev(x, v, lr=lrate + 1e-6)[2] - ev(x, v, lr=lrate - 1e-6)[2]) / 4e-6
        assert dl == pytest.approx(du + dd, rel=1e-6)


@pytest.fixture(scope="module")
def mixed_damped():
    """The mixed model with both materials damped (τ = 0.02 s steel, 0.05 s soft)."""
    import dataclasses

    from flexmb_core.model.compile import compile_scene
    from flexmb_core.simulator import Simulator
    model, _ = _mixed_scene()
    scene = model.scene
    mats = {k: dataclasses.replace(m, eta=m.E * (0.02 if k == "steel" else 0.05)) for k, m in scene.materials.items()}
    model = compile_scene(dataclasses.replace(scene, materials=mats))
    sim = Simulator(model)
    update_load_scales(model, sim.ws, 0.0)
    return model, sim


def test_damped_global_tangent_matches_finite_difference(mixed_damped):
    """The Newton matrix of a damped model: d r(q, v(q))/dq with v(q) = v̂ + c_v q (integrator
    rates, c_v = γ/(βΔt)), actuators at λ ≠ 1 with λ̇ ≠ 0."""
    import scipy.sparse as sp
    model, sim = mixed_damped
    assert model.material_damping
    ws = sim.ws
    lam, lam_rate = np.array([1.15, 0.9]), np.array([0.4, -0.7])
    q = _perturbed(model, 0.03, seed=4)
    v = np.random.default_rng(7).standard_normal(model.ndof)
    c_v = 40.0
    assemble(model, ws, q, lam, True, v=v, lam_rate=lam_rate, c_v=c_v)
    k = sp.csr_matrix((ws.kdata.copy(), model.indices, model.indptr), shape=(model.nfree,) * 2).toarray()
    free = model.free
    h = 1e-7
    kfd = np.zeros_like(k)
    for j, dof in enumerate(free):
        rs = []
        for sgn in (1, -1):
            qq, vv = q.copy(), v.copy()
            qq[dof] += sgn * h
            vv[dof] += sgn * c_v * h
            assemble(model, ws, qq, lam, False, v=vv, lam_rate=lam_rate)
            rs.append(ws.r[free].copy())
        kfd[:, j] = (rs[0] - rs[1]) / (2 * h)
    err = np.abs(k - kfd).max() / np.abs(k).max()
    assert err < 1e-7, f"damped tangent differs from the finite difference by {err:.2e}"


def _rigid_velocity(model, q, omega, u):
    """v = ω × x + u at positions, ω × V at section vectors."""
    pos = np.zeros(model.ndof, dtype=bool)
    pos[model.node_ydofs.ravel()] = True
    v3 = np.cross(omega, q.reshape(-1, 3))
    v3[pos.reshape(-1, 3)[:, 0]] += u
    return v3.ravel()


def test_viscous_force_vanishes_under_rigid_velocity(mixed_damped):
    """A deformed, stressed model moving rigidly (translation + rotation): zero viscous force and
    zero dissipation, while a deforming velocity of the same size is damped."""
    model, sim = mixed_damped
    ws = sim.ws
    ws.follower_scale[:] = 0.0
    ws.cons_scale[:] = 0.0
    lam = np.array([1.1, 0.93])
    q = _perturbed(model, 0.03, seed=2)
    assemble(model, ws, q, lam, False)
    r_el = ws.r.copy()
    v_rigid = _rigid_velocity(model, q, np.array([0.8, -1.3, 2.1]), np.array([1.5, -0.4, 0.9]))
    assemble(model, ws, q, lam, False, v=v_rigid)
    viscous = np.abs(ws.r - r_el).max()
    assert ws.dissipation < 1e-9
    v_def = np.random.default_rng(3).standard_normal(model.ndof) * np.abs(v_rigid).max()
    assemble(model, ws, q, lam, False, v=v_def)
    damped = np.abs(ws.r - r_el).max()
    assert ws.dissipation > 0.0
    assert viscous < 1e-10 * damped, f"rigid velocity gives viscous force {viscous:.2e} N (deforming: {damped:.2e} N)"
    update_load_scales(model, ws, 0.0)


def test_commanded_extension_is_not_damped(mixed_damped):
    """Actuators stretched uniformly at the commanded rate (v = λ̇/λ · (x − x₀) along the axis,
    λ̇ given): stress-free, so no viscous force either."""
    model, sim = mixed_damped
    ws = sim.ws
    lam = np.array([1.25, 0.8])
    lam_rate = np.array([0.6, -0.3])
    for ia, name in enumerate(model.actuators.names):
        info = model.member(name)
        q = model.q0.copy()
        v = np.zeros(model.ndof)
        x0 = model.q0[info.ydofs[0]]
        for k in range(info.ydofs.shape[0]):
            rel = model.q0[info.ydofs[k]] - x0
            q[info.ydofs[k]] = x0 + lam[ia] * rel
            v[info.ydofs[k]] = lam_rate[ia] * rel
        out = np.zeros(2)
        from flexmb_core.model.assembly import actuator_dudlam
        actuator_dudlam(model, ws, q, lam, v=v, lam_rate=lam_rate)
        out[:] = ws.dudlam
        assert abs(out[ia]) < 1e-6
        # and a mismatched rate is damped: the conjugate force changes
        actuator_dudlam(model, ws, q, lam, v=v, lam_rate=lam_rate * 1.5)
        assert abs(ws.dudlam[ia]) > 1e-3


def test_dissipation_is_non_negative_and_equals_viscous_power(mixed_damped):
    """2D = v·f_visc + Σ_a (∂D/∂λ̇_a) λ̇_a ≥ 0 for arbitrary states (Euler's theorem for the
    quadratic dissipation potential)."""
    from flexmb_core.model.assembly import actuator_dudlam
    model, sim = mixed_damped
    ws = sim.ws
    ws.follower_scale[:] = 0.0
    ws.cons_scale[:] = 0.0
    rng = np.random.default_rng(11)
    for trial in range(20):
        q = _perturbed(model, 0.05, seed=100 + trial)
        lam = rng.uniform(0.8, 1.2, 2)
        v = rng.standard_normal(model.ndof)
        lam_rate = rng.standard_normal(2)
        assemble(model, ws, q, lam, False)
        r_el = ws.r.copy()
        assemble(model, ws, q, lam, False, v=v, lam_rate=lam_rate)
        p = ws.dissipation
        assert p >= 0.0
        f_visc = ws.r - r_el
        g_el = actuator_dudlam(model, ws, q, lam).copy()
        g_visc = actuator_dudlam(model, ws, q, lam, v=v, lam_rate=lam_rate) - g_el
        assert v @ f_visc + g_visc @ lam_rate == pytest.approx(p, rel=1e-9)
    update_load_scales(model, ws, 0.0)
