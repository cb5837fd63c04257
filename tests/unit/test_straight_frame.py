"""The straight-element frame kernel (F̃ affine in the section coordinates, section integrals from
the rule's moments): the same residual, energy, tangent, dissipation and actuator force as the
general kernel — undamped, Kelvin–Voigt damped, actuated (λ, λ̇), both — a tangent that is the
derivative of its residual (∂r/∂q at fixed v, and ∂r/∂v), no force under rigid motion and no
viscous force under rigid rates, and only curved elements keep the general kernel."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from builders import build, cantilever
from flexmb_core.kernels.frame3d import (frame_element, frame_group, frame_group_actuator_dudlam, frame_scratch,
                                         frame_structure, straight_frame_element)

SECTIONS = [{"shape": "circle", "radius": 0.01}, {"shape": "rectangle", "width": 0.02, "height": 0.03},
            {"shape": "tube", "outer_radius": 0.015, "thickness": 0.003}]
TAU = 1.31e-5          # s: the shipped legs' retardation time η/E (scenes/stewart_platform*.yaml)


def _element(order, section, tau=0.0, elements=3):
    d = cantilever(length=1.0, elements=elements, order=order, E=2e11, nu=0.3, section=section)
    d["materials"]["m"]["eta"] = tau * 2e11    # Kelvin–Voigt: retardation time τ = η/E
    model, _ = build(d)
    g = model.frame_groups[0]
    assert g.mat[0, 6] == pytest.approx(tau, rel=1e-15)
    return model, g, frame_structure(g), frame_scratch(g.w.shape[1], g.dax.shape[2])


def _straight(g, st, sc, e, q, lam, want_k, v=None, lam_rate=0.0, c_v=0.0, want_dlam=False):
    n = q.size
    re, ke = np.zeros(n), np.zeros((n, n))
    v = np.zeros(n) if v is None else v
    u, dl, dp = straight_frame_element(q, v, st[1][e], st[2][e], st[3][e], g.w[e], g.nsec, g.mat[e], lam, lam_rate,
                                       c_v, want_k, want_dlam, st[4], st[5], st[6], st[7], st[8], st[9][e], re, ke)
    return u, re, ke, dl, dp


def _general(g, sc, e, q, lam, v=None, lam_rate=0.0, c_v=0.0, want_dlam=False):
    d_, fp, fd, ep, ed, bm, bd, gb, gd, _, _, _, _, kn = sc
    n = q.size
    re, ke = np.zeros(n), np.zeros((n, n))
    v = np.zeros(n) if v is None else v
    u, dl, dp = frame_element(q, v, g.dax[e], g.dsec[e], g.w[e], g.nsec, g.mat[e], lam, lam_rate, c_v, True,
                              want_dlam, d_, fp, fd, ep, ed, bm, bd, gb, gd, re, ke, kn)
    return u, re, ke, dl, dp


def _state(model, g, e, seed, amp=0.05, rate=2.0):
    """A large random perturbation of element e's reference (stretched, bent, twisted, sheared
    sections) and random rates of the same order (1/s)."""
    rng = np.random.default_rng(seed)
    q = model.q0[g.edofs[e]] + amp * rng.standard_normal(g.edofs.shape[1])
    v = rate * amp * rng.standard_normal(q.size)
    return q, v


def _rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("section", SECTIONS, ids=lambda s: s["shape"])
@pytest.mark.parametrize("lam", [1.0, 1.2])
def test_equals_the_general_kernel(order, section, lam):
    """Undamped, large random perturbation, actuator stretch λ: energy, residual, tangent and ∂U/∂λ
    agree to round-off (measured ≤ 1e-14 relative); the tangent is exactly symmetric."""
    model, g, st, sc = _element(order, section)
    assert st[0].all()
    q, _ = _state(model, g, 1, order)
    u1, r1, k1, l1, d1 = _general(g, sc, 1, q, lam, want_dlam=True)
    u2, r2, k2, l2, d2 = _straight(g, st, sc, 1, q, lam, True, want_dlam=True)
    assert u2 == pytest.approx(u1, rel=1e-12)
    assert l2 == pytest.approx(l1, rel=1e-12)
    assert d1 == d2 == 0.0
    assert _rel(r2, r1) <= 1e-12
    assert _rel(k2, k1) <= 1e-12
    assert np.array_equal(k2, k2.T)


CASES = {"damped": (TAU, 1.0, 0.0), "actuated": (0.0, 1.15, 0.4), "damped_actuated": (TAU, 1.15, 0.4),
         "damped_actuated_shortening": (1e-3, 0.9, -0.7)}


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("section", SECTIONS, ids=lambda s: s["shape"])
@pytest.mark.parametrize("case", list(CASES), ids=list(CASES))
def test_damped_and_actuated_equal_the_general_kernel(order, section, case):
    """Kelvin–Voigt damping with random rates v, stretch rate λ̇, c_v = γ/(βΔt) of a 1 ms step:
    energy, ∂U/∂λ + ∂D/∂λ̇, dissipation 2D, residual and the non-symmetric tangent ∂r/∂q + c_v ∂r/∂v
    agree with :func:`frame_element` to ≤ 1e-12 relative (measured ≤ 2e-14)."""
    tau, lam, lam_rate = CASES[case]
    model, g, st, sc = _element(order, section, tau)
    assert st[0].all()
    q, v = _state(model, g, 1, 10 + order)
    c_v = 0.5 / (0.25 * 1e-3)
    u1, r1, k1, l1, d1 = _general(g, sc, 1, q, lam, v, lam_rate, c_v, want_dlam=True)
    u2, r2, k2, l2, d2 = _straight(g, st, sc, 1, q, lam, True, v, lam_rate, c_v, want_dlam=True)
    assert u2 == pytest.approx(u1, rel=1e-12)
    assert l2 == pytest.approx(l1, rel=1e-12)
    assert d2 == pytest.approx(d1, rel=1e-12, abs=0.0 if tau else 1e-300)
    assert _rel(r2, r1) <= 1e-12
    assert _rel(k2, k1) <= 1e-12
    if tau:
        assert d1 > 0.0
        assert _rel(k2 - k2.T, k1 - k1.T) <= 1e-9        # the viscous non-symmetric part by itself (3e-11)
        assert not np.allclose(k1, k1.T, rtol=0.0, atol=1e-9 * np.abs(k1).max())   # really non-symmetric


def _fd_jacobians(g, st, sc, e, q, v, lam, lam_rate, h=1e-7):
    """Central differences of the residual: ∂r/∂q at fixed v and ∂r/∂v at fixed q."""
    n = q.size
    kq, kv = np.zeros((n, n)), np.zeros((n, n))
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = h
        kq[:, j] = (_straight(g, st, sc, e, q + dq, lam, False, v, lam_rate)[1]
                    - _straight(g, st, sc, e, q - dq, lam, False, v, lam_rate)[1]) / (2 * h)
        kv[:, j] = (_straight(g, st, sc, e, q, lam, False, v + dq, lam_rate)[1]
                    - _straight(g, st, sc, e, q, lam, False, v - dq, lam_rate)[1]) / (2 * h)
    return kq, kv


@pytest.mark.parametrize("section", SECTIONS, ids=lambda s: s["shape"])
def test_tangent_is_the_derivative_of_the_residual(section):
    model, g, st, sc = _element(3, section)
    q, _ = _state(model, g, 0, 3, amp=0.03)
    k = _straight(g, st, sc, 0, q, 1.1, True)[2]
    kq, _ = _fd_jacobians(g, st, sc, 0, q, 0 * q, 1.1, 0.0)
    assert np.abs(k - kq).max() <= 1e-6 * np.abs(k).max()


@pytest.mark.parametrize("section", SECTIONS, ids=lambda s: s["shape"])
def test_damped_tangent_is_the_derivative_of_the_residual(section):
    """Damped, actuated (λ = 1.1, λ̇ = 0.5/s), random rates: the kernel's tangent with c_v = 0 is
    ∂r/∂q at fixed v, the difference of two c_v is c_v ∂r/∂v, both against central differences
    (measured ~1e-9 relative, the step's truncation)."""
    tau = 2e-3                       # a visible viscous part: τ·|Ė| ~ 1e-3 of the elastic stress
    model, g, st, sc = _element(3, section, tau)
    q, v = _state(model, g, 0, 4, amp=0.03)
    lam, lam_rate, c_v = 1.1, 0.5, 1e3
    k0 = _straight(g, st, sc, 0, q, lam, True, v, lam_rate, 0.0)[2]
    k1 = _straight(g, st, sc, 0, q, lam, True, v, lam_rate, c_v)[2]
    kq, kv = _fd_jacobians(g, st, sc, 0, q, v, lam, lam_rate)
    assert np.abs(k0 - kq).max() <= 1e-6 * np.abs(k0).max()
    dv = (k1 - k0) / c_v
    assert np.abs(dv - kv).max() <= 1e-6 * np.abs(kv).max()
    assert np.abs(k0 - k0.T).max() > 1e-4 * np.abs(k0).max()      # the viscous part is non-symmetric


def _rigid(model, g, e, rot, shift):
    q = model.q0[g.edofs[e]].reshape(-1, 3) @ rot.T
    q[0::3] += shift                                    # positions also translate
    return q


def test_rigid_motion_is_force_free():
    model, g, st, sc = _element(3, SECTIONS[1])
    rot = Rotation.from_rotvec([0.7, -1.9, 2.4]).as_matrix()
    q = _rigid(model, g, 2, rot, np.array([0.3, -2.0, 5.0])).ravel()
    u, r, _, _, _ = _straight(g, st, sc, 2, q, 1.0, False)
    force_scale = g.mat[2, 0] * g.w[2].sum()               # E·V (N·m), as in test_kernels
    assert abs(u) < 1e-24 * force_scale
    assert np.abs(r).max() < 1e-12 * force_scale           # measured 1.4e-6 N of E·V = 4e7


@pytest.mark.parametrize("section", SECTIONS, ids=lambda s: s["shape"])
def test_rigid_rates_are_not_damped(section):
    """Rigidly rotated and translated element with a rigid velocity field (v_Y = ω×Y + u, v_V =
    ω×V): Ė = 0, so no viscous force and no dissipation; the force equals the undamped one."""
    tau = 1e-2                                          # large: any viscous leak would show
    model, g, st, sc = _element(3, section, tau)
    rot = Rotation.from_rotvec([0.4, 1.3, -0.8]).as_matrix()
    q = _rigid(model, g, 1, rot, np.array([1.0, 0.5, -0.2]))
    omega = np.array([3.0, -7.0, 5.0])                  # rad/s
    v = np.cross(omega, q)
    v[0::3] += np.array([2.0, -1.0, 0.5])               # m/s, positions only
    q, v = q.ravel(), v.ravel()
    force_scale = g.mat[2, 0] * g.w[1].sum()
    _, r, _, _, dp = _straight(g, st, sc, 1, q, 1.0, False, v)
    assert np.abs(r).max() < 1e-12 * force_scale
    assert abs(dp) < 1e-24 * force_scale * tau * 10.0
    # the same with a stretched, bent state: the rigid rate adds nothing to the elastic force
    q2, _ = _state(model, g, 1, 7)
    q2 = (q2.reshape(-1, 3) @ rot.T).ravel()
    v2 = np.cross(omega, q2.reshape(-1, 3))
    v2[0::3] += np.array([2.0, -1.0, 0.5])
    _, r_el, _, _, _ = _straight(g, st, sc, 1, q2, 1.0, False)
    _, r_v, _, _, dp2 = _straight(g, st, sc, 1, q2, 1.0, False, v2.ravel())
    _, _, _, _, dp_ref = _straight(g, st, sc, 1, q2, 1.0, False, _state(model, g, 1, 8, rate=20.0)[1])
    assert np.abs(r_v - r_el).max() < 1e-12 * np.abs(r_el).max()
    assert 0.0 <= dp2 < 1e-12 * dp_ref


def test_group_paths_agree_for_damped_actuators():
    """frame_group through the straight and the general paths (flags on/off) on a damped actuated
    member: residual, tangent, energy and dissipation agree to 1e-12; so do the actuator forces of
    frame_group_actuator_dudlam through either path."""
    model, g, _, sc = _element(3, SECTIONS[2], TAU)
    act = np.zeros_like(g.act)                           # all three elements driven by actuator 0
    act.setflags(write=False)                            # as the model's: one compiled signature
    lam, lam_rate = np.array([1.07]), np.array([0.3])
    rng = np.random.default_rng(5)
    q = model.q0 + 0.02 * rng.standard_normal(model.ndof)
    v = 0.1 * rng.standard_normal(model.ndof)
    c_v = 2e3
    out = []
    for structured in (True, False):
        st = frame_structure(g, structured=structured)
        assert st[0].all() == structured
        r, kd = np.zeros(model.ndof), np.zeros(model.nnz)
        u, dp = frame_group(q, v, g.edofs, g.dax, g.dsec, g.w, g.nsec, g.mat, act, lam, lam_rate, c_v, g.smap, True,
                            False, r, kd, *sc, *st)
        out.append((u, dp, r, kd))
    (u1, d1, r1, k1), (u2, d2, r2, k2) = out
    assert u1 == pytest.approx(u2, rel=1e-12)
    assert d1 == pytest.approx(d2, rel=1e-12)
    assert _rel(r1, r2) <= 1e-12
    assert _rel(k1, k2) <= 1e-12
    st = frame_structure(g)
    ref = sum(_straight(g, st, sc, e, q[g.edofs[e]].copy(), lam[0], False, v[g.edofs[e]].copy(), lam_rate[0],
                        want_dlam=True)[3] for e in range(g.edofs.shape[0]))
    for structured in (True, False):          # the actuator force through either path
        dl = np.zeros(1)
        frame_group_actuator_dudlam(q, v, g.edofs, g.dax, g.dsec, g.w, g.nsec, g.mat, act, lam, lam_rate, 0.0,
                                    False, True, dl, *sc, *frame_structure(g, structured=structured))
        assert dl[0] == pytest.approx(ref, rel=1e-12)


def test_every_straight_element_takes_it():
    model, _ = build(cantilever(length=1.0, elements=2, order=3, arc_center=[0.5, -1.0, 0.0]))
    assert not frame_structure(model.frame_groups[0])[0].any()              # curved
    d = cantilever(length=1.0, elements=2, order=3)
    d["materials"]["m"]["eta"] = 1e5
    model, _ = build(d)
    assert model.frame_groups[0].mat[:, 6].min() > 0.0
    assert frame_structure(model.frame_groups[0])[0].all()                  # damped: straight too
    model, _ = build(cantilever(length=1.0, elements=2, order=3))
    assert frame_structure(model.frame_groups[0])[0].all()
    assert not frame_structure(model.frame_groups[0], structured=False)[0].any()
