"""The straight-element frame kernel (F̃ affine in the section coordinates): the same residual,
energy and tangent as the general kernel, a tangent that is the derivative of its residual, no
force under rigid motion, and only straight undamped elements take it."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from builders import build, cantilever
from flexmb_core.kernels.frame3d import frame_element, frame_scratch, frame_structure, straight_frame_element

SECTIONS = [{"shape": "circle", "radius": 0.01}, {"shape": "rectangle", "width": 0.02, "height": 0.03},
            {"shape": "tube", "outer_radius": 0.015, "thickness": 0.003}]


def _element(order, section):
    model, _ = build(cantilever(length=1.0, elements=3, order=order, E=2e11, nu=0.3, section=section))
    g = model.frame_groups[0]
    return model, g, frame_structure(g), frame_scratch(g.w.shape[1], g.dax.shape[2])


def _straight(g, st, sc, e, q, lam, want_k):
    fp, ep, gb = sc[1], sc[3], sc[7]
    n = q.size
    re, ke = np.zeros(n), np.zeros((n, n))
    u = straight_frame_element(q, st[1][e], st[2][e], st[3][e], g.w[e], g.nsec, g.mat[e], lam, want_k, st[4], fp,
                               ep, gb, st[5], st[6], st[7], st[8], re, ke)
    return u, re, ke


def _general(g, sc, e, q, lam):
    d_, fp, fd, ep, ed, bm, bd, gb, gd, _, _, _, _, kn = sc
    n = q.size
    re, ke = np.zeros(n), np.zeros((n, n))
    u, _, _ = frame_element(q, 0 * q, g.dax[e], g.dsec[e], g.w[e], g.nsec, g.mat[e], lam, 0.0, 0.0, True, False,
                            d_, fp, fd, ep, ed, bm, bd, gb, gd, re, ke, kn)
    return u, re, ke


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("section", SECTIONS, ids=lambda s: s["shape"])
@pytest.mark.parametrize("lam", [1.0, 1.2])
def test_equals_the_general_kernel(order, section, lam):
    """Large random perturbation, actuator stretch λ: energy, residual and tangent agree to
    round-off (measured ≤ 1e-14 relative)."""
    model, g, st, sc = _element(order, section)
    assert st[0].all()
    rng = np.random.default_rng(order)
    q = model.q0[g.edofs[1]] + 0.05 * rng.standard_normal(g.edofs.shape[1])
    u1, r1, k1 = _general(g, sc, 1, q, lam)
    u2, r2, k2 = _straight(g, st, sc, 1, q, lam, True)
    assert u2 == pytest.approx(u1, rel=1e-12)
    assert np.abs(r2 - r1).max() <= 1e-12 * np.abs(r1).max()
    assert np.abs(k2 - k1).max() <= 1e-12 * np.abs(k1).max()
    assert np.array_equal(k2, k2.T)


@pytest.mark.parametrize("section", SECTIONS, ids=lambda s: s["shape"])
def test_tangent_is_the_derivative_of_the_residual(section):
    model, g, st, sc = _element(3, section)
    rng = np.random.default_rng(3)
    q = model.q0[g.edofs[0]] + 0.03 * rng.standard_normal(g.edofs.shape[1])
    _, r0, k = _straight(g, st, sc, 0, q, 1.1, True)
    h = 1e-7
    kfd = np.zeros_like(k)
    for j in range(q.size):
        qp, qm = q.copy(), q.copy()
        qp[j] += h
        qm[j] -= h
        kfd[:, j] = (_straight(g, st, sc, 0, qp, 1.1, False)[1] - _straight(g, st, sc, 0, qm, 1.1, False)[1]) / (2 * h)
    assert np.abs(k - kfd).max() <= 1e-6 * np.abs(k).max()


def test_rigid_motion_is_force_free():
    model, g, st, sc = _element(3, SECTIONS[1])
    rot = Rotation.from_rotvec([0.7, -1.9, 2.4]).as_matrix()
    q = model.q0[g.edofs[2]].reshape(-1, 3) @ rot.T
    q[0::3] += np.array([0.3, -2.0, 5.0])                 # positions also translate
    u, r, _ = _straight(g, st, sc, 2, q.ravel(), 1.0, False)
    force_scale = g.mat[2, 0] * g.w[2].sum()               # E·V (N·m), as in test_kernels
    assert abs(u) < 1e-24 * force_scale
    assert np.abs(r).max() < 1e-12 * force_scale           # measured 1.4e-6 N of E·V = 4e7


def test_only_straight_undamped_elements_take_it():
    model, _ = build(cantilever(length=1.0, elements=2, order=3, arc_center=[0.5, -1.0, 0.0]))
    assert not frame_structure(model.frame_groups[0])[0].any()              # curved
    d = cantilever(length=1.0, elements=2, order=3)
    d["materials"]["m"]["eta"] = 1e5
    model, _ = build(d)
    assert not frame_structure(model.frame_groups[0])[0].any()              # damped
    model, _ = build(cantilever(length=1.0, elements=2, order=3))
    assert frame_structure(model.frame_groups[0])[0].all()
    assert not frame_structure(model.frame_groups[0], structured=False)[0].any()
