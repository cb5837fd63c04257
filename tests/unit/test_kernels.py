"""Element kernels: tangent = finite difference of the residual, residual = gradient of the
energy, zero energy and force under rigid motion, actuators stress-free at the commanded length."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from builders import build, cantilever
from flexmb_core.kernels.frame3d import frame_element
from flexmb_core.kernels.truss import truss_element
from flexmb_core.model.assembly import assemble, update_load_scales


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
    d_, fp, ep, bm, gb, _, re, ke = sc
    rng = np.random.default_rng(order)
    qe = model.q0[g.edofs[0]] + 0.05 * rng.standard_normal(g.edofs.shape[1])
    for lam in (1.0, 1.2):
        def ev(x):
            r = np.zeros_like(re)
            k = np.zeros_like(ke)
            u, dl = frame_element(x, g.dax[0], g.dsec[0], g.w[0], g.nsec, g.mat[0], lam, True, True,
                                  d_, fp, ep, bm, gb, r, k)
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
            return frame_element(qe, g.dax[0], g.dsec[0], g.w[0], g.nsec, g.mat[0], l, False, False,
                                 d_, fp, ep, bm, gb, np.zeros_like(re), np.zeros_like(ke))[0]
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
            d_, fp, ep, bm, gb, _, re, ke = ws.frame_scratch[gi]
            for e in np.nonzero(g.act == ia)[0]:
                u, _ = frame_element(q[g.edofs[e]], g.dax[e], g.dsec[e], g.w[e], g.nsec, g.mat[e], lam[ia],
                                     False, False, d_, fp, ep, bm, gb, re, ke)
                assert abs(u) < 1e-20
                assert np.abs(re).max() < 1e-6
        else:
            t = model.truss
            for e in np.nonzero(t.act == ia)[0]:
                re = np.zeros(6)
                u, _ = truss_element(q[t.edofs[e]], t.l0[e], t.ea[e], lam[ia], False, re, np.zeros((6, 6)))
                assert abs(u) < 1e-20
                assert np.abs(re).max() < 1e-6


def test_truss_tangent_and_actuator_derivative():
    rng = np.random.default_rng(5)
    x = np.array([0.1, -0.2, 0.3, 1.2, 0.4, -0.1])
    for lam in (1.0, 0.7, 1.4):
        re = np.zeros(6)
        ke = np.zeros((6, 6))
        u, dl = truss_element(x, 1.1, 3.0e6, lam, True, re, ke)
        h = 1e-7
        kfd = np.zeros((6, 6))
        gfd = np.zeros(6)
        for j in range(6):
            e = np.zeros(6)
            e[j] = h
            rp, rm = np.zeros(6), np.zeros(6)
            up, _ = truss_element(x + e, 1.1, 3.0e6, lam, False, rp, ke * 0)
            um, _ = truss_element(x - e, 1.1, 3.0e6, lam, False, rm, ke * 0)
            kfd[:, j] = (rp - rm) / (2 * h)
            gfd[j] = (up - um) / (2 * h)
        re2 = np.zeros(6)
        truss_element(x, 1.1, 3.0e6, lam, True, re2, ke)
        assert np.allclose(re2, gfd, rtol=1e-6, atol=1e-6 * np.abs(re2).max())
        assert np.allclose(ke, kfd, rtol=1e-6, atol=1e-6 * np.abs(ke).max())
        up, _ = truss_element(x, 1.1, 3.0e6, lam + 1e-7, False, re, ke)
        um, _ = truss_element(x, 1.1, 3.0e6, lam - 1e-7, False, re, ke)
        assert dl == pytest.approx((up - um) / 2e-7, rel=1e-6)
    del rng


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
