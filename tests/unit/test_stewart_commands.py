"""Stewart platform command (paper appendix Eqs. 52-60): geometry, rigid motion, rates, blending."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.mechanisms.stewart import (
    H0,
    R_MAX,
    T_END,
    StewartGeometry,
    appendix_leg_lengths,
    appendix_platform_outputs,
    appendix_pose,
    appendix_vertex_displacements,
    appendix_vertex_displacements_literal,
    appendix_vertex_positions,
    blend_quintic,
    read_command_table,
    rotation_x,
    rotation_z,
    write_command_table,
)

L0 = 1.0513
GEOM = StewartGeometry.default()
T_GRID = np.linspace(0.0, T_END, 4001)  # 5 ms samples over the whole law


def _smooth_times(n: int = 400) -> np.ndarray:
    """Times away from the t = 10 s kink of the exact law (velocity jumps there)."""
    t = np.linspace(0.01, T_END - 0.01, n)
    return t[np.abs(t - 10.0) > 0.01]


def _edge_lengths(p: np.ndarray) -> np.ndarray:
    """|AB|, |BC|, |CA| for vertex positions (n, 3, 3) -> (n, 3)."""
    return np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2)


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of scalar-first unit quaternions (n, 4)."""
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


# --- geometry -------------------------------------------------------------------------------
def test_initial_leg_lengths_equal_paper_value():
    lay = GEOM.layout()
    assert lay.base_points.shape == (6, 3) and lay.vertices0.shape == (3, 3)
    np.testing.assert_array_equal(lay.leg_vertex, [0, 0, 1, 1, 2, 2])
    np.testing.assert_allclose(lay.lengths0, L0, rtol=0, atol=1e-12)
    assert GEOM.base_offset == pytest.approx(math.sqrt(L0**2 - 1.0), abs=1e-15)
    assert GEOM.base_offset == pytest.approx(0.3244, abs=1e-4)
    np.testing.assert_array_equal(lay.base_points[:, 2], 0.0)


def test_platform_triangle_and_base_pairs():
    offs = GEOM.vertex_offsets()
    np.testing.assert_allclose(offs.mean(axis=0), 0.0, atol=1e-15)  # G is the centroid
    np.testing.assert_allclose(_edge_lengths(offs[None])[0], 1.0, atol=1e-15)
    np.testing.assert_allclose(offs[0], [0.0, 2 * math.sqrt(3) / 6, 0.0], atol=1e-15)
    lay = GEOM.layout()
    for v in range(3):
        a, b = lay.base_points[2 * v : 2 * v + 2]
        proj = offs[v, :2]
        # The pair straddles the vertex projection symmetrically, tangentially at distance d.
        np.testing.assert_allclose(0.5 * (a[:2] + b[:2]), proj, atol=1e-15)
        assert abs(np.dot(a[:2] - proj, proj)) < 1e-15
        assert np.linalg.norm(a[:2] - proj) == pytest.approx(GEOM.base_offset, abs=1e-15)


def test_geometry_rejects_legs_shorter_than_height():
    with pytest.raises(ValueError, match="leg_length must exceed height"):
        StewartGeometry(height=1.2)


# --- rotation conventions and the paper's Eqs. 55-57 ------------------------------------------
def test_rotation_conventions_are_right_handed():
    ex, ey, ez = np.eye(3)
    np.testing.assert_allclose(rotation_z(math.pi / 2)[0] @ ex, ey, atol=1e-16)
    np.testing.assert_allclose(rotation_x(math.pi / 2)[0] @ ey, ez, atol=1e-16)


def test_eq55_fixes_the_sign_convention():
    # Eq. 55's γ-term for A_rel = (0, a, 0) is (-a sin γ, a(cos γ - 1), 0): R_z(+γ) reproduces it,
    # the transposed (clockwise) convention flips the x-component.
    a, g = 2 * GEOM.triangle_height / 3, 0.4
    A = np.array([0.0, a, 0.0])
    eq55 = np.array([-a * math.sin(g), a * (math.cos(g) - 1), 0.0])
    np.testing.assert_allclose(rotation_z(g)[0] @ A - A, eq55, atol=1e-16)
    assert np.abs(rotation_z(g)[0].T @ A - A - eq55).max() > 0.1
    eq55_beta = np.array([0.0, a * (math.cos(g) - 1), a * math.sin(g)])
    np.testing.assert_allclose(rotation_x(g)[0] @ A - A, eq55_beta, atol=1e-16)
    assert np.abs(rotation_x(g)[0].T @ A - A - eq55_beta).max() > 0.1


def test_literal_equations_match_rigid_motion_except_eq56_y_sign():
    d_lit = appendix_vertex_displacements_literal(T_GRID)
    d_rig = appendix_vertex_displacements(T_GRID)
    # A (Eq. 55) and C (Eq. 57) are exactly the rigid rotation.
    np.testing.assert_allclose(d_lit[:, 0], d_rig[:, 0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(d_lit[:, 2], d_rig[:, 2], rtol=0, atol=1e-14)
    # B (Eq. 56): x and z agree; y has +ℓ/2 sin γ instead of -ℓ/2 sin γ, a difference ℓ sin γ.
    np.testing.assert_allclose(d_lit[:, 1, [0, 2]], d_rig[:, 1, [0, 2]], rtol=0, atol=1e-14)
    gamma = np.where(T_GRID <= 10.0, math.pi / 4 * np.sin(math.pi * T_GRID / 10), 0.0)
    diff = d_lit[:, 1, 1] - d_rig[:, 1, 1]
    np.testing.assert_allclose(diff, GEOM.side * np.sin(gamma), rtol=0, atol=1e-14)
    assert diff.max() == pytest.approx(GEOM.side * math.sin(math.pi / 4), abs=1e-6)
    # The literal B is not rigid: the edge AB changes length while γ is active.
    p_lit = GEOM.centroid0() + GEOM.vertex_offsets() + d_lit
    assert np.abs(_edge_lengths(p_lit) - GEOM.side).max() > 0.1


@pytest.mark.parametrize("start", ["exact", "blended"])
def test_vertex_motion_is_rigid(start):
    p, _ = appendix_vertex_positions(T_GRID, start=start)
    np.testing.assert_allclose(_edge_lengths(p), GEOM.side, rtol=0, atol=1e-12)
    p_G, R = appendix_pose(T_GRID, start=start)
    np.testing.assert_allclose(p.mean(axis=1), p_G, rtol=0, atol=1e-14)
    eye = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), eye, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)


def test_centroid_law_values():
    # Eq. 52 at t = 5 s (ψ = π, R = R_max/2), t = 10 s (ψ = 2π) and t = 20 s.
    p_G, _ = appendix_pose([5.0, 10.0, 20.0])
    d = p_G - GEOM.centroid0()
    np.testing.assert_allclose(d[0], [0.0, -R_MAX / 2, 0.0], atol=1e-15)
    np.testing.assert_allclose(d[1], [0.0, R_MAX, 0.0], atol=1e-15)
    np.testing.assert_allclose(d[2], [0.0, R_MAX, 0.0], atol=1e-15)
    # Peak heave at t = 1.25 s is h0/2.
    assert appendix_pose(1.25)[0][0, 2] - 1.0 == pytest.approx(H0 / 2, abs=1e-15)


# --- leg lengths and rates -----------------------------------------------------------------
def test_leg_lengths_start_at_l0_and_stay_in_stroke():
    L, _ = appendix_leg_lengths(np.linspace(0.0, T_END, 20001))
    np.testing.assert_allclose(L[0], L0, rtol=0, atol=1e-12)  # ΔL_i(0) = 0 (Eq. 60)
    # Extremes stated in the module docstring.
    assert L.min() == pytest.approx(0.72163, abs=1e-5)
    assert L.max() == pytest.approx(1.54214, abs=1e-5)
    assert L.min() > 0.7 and L.max() < 1.6


@pytest.mark.parametrize("start", ["exact", "blended"])
def test_rates_match_central_differences(start):
    t, h = _smooth_times(), 1e-5
    L, Ld = appendix_leg_lengths(t, start=start)
    Lp, _ = appendix_leg_lengths(t + h, start=start)
    Lm, _ = appendix_leg_lengths(t - h, start=start)
    np.testing.assert_allclose(Ld, (Lp - Lm) / (2 * h), rtol=0, atol=1e-8)
    assert np.abs(Ld).max() > 0.1  # the check is not vacuous
    _, v = appendix_vertex_positions(t, start=start)
    pp, _ = appendix_vertex_positions(t + h, start=start)
    pm, _ = appendix_vertex_positions(t - h, start=start)
    np.testing.assert_allclose(v, (pp - pm) / (2 * h), rtol=0, atol=1e-8)


def test_exact_law_initial_rates_equal_derived_values():
    # Derived: ẋ_G = 0, ẏ_G = d/dt[R(ψ) cos ψ](0) = R_max ψ̇/(2π) = R_max/10, ż_G = (h0/2)(2π/5),
    # γ̇ = π²/40 about z, so ṗ_X = ḋ_G + γ̇ e_z × X_rel.
    d_dot = np.array([0.0, R_MAX / 10, 0.5 * H0 * 2 * math.pi / 5])
    gamma_dot = math.pi**2 / 40
    assert d_dot[1] == pytest.approx(0.03) and d_dot[2] == pytest.approx(0.15 * 2 * math.pi / 5)
    offs = GEOM.vertex_offsets()
    v_expected = d_dot + gamma_dot * np.cross([0.0, 0.0, 1.0], offs)
    _, v = appendix_vertex_positions(0.0)
    np.testing.assert_allclose(v[0], v_expected, rtol=0, atol=1e-15)
    lay = GEOM.layout()
    r = lay.vertices0[lay.leg_vertex] - lay.base_points
    Ld_expected = np.einsum("lk,lk->l", r, v_expected[lay.leg_vertex]) / L0
    _, Ld = appendix_leg_lengths(0.0)
    np.testing.assert_allclose(Ld[0], Ld_expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(
        Ld[0], [0.22325, 0.13534, 0.21524, 0.14336, 0.23127, 0.12732], atol=1e-5
    )
    # One-sided second-order difference of the pose confirms the centroid rate at t = 0.
    h = 1e-4
    p = appendix_pose([0.0, h, 2 * h])[0]
    np.testing.assert_allclose((-3 * p[0] + 4 * p[1] - p[2]) / (2 * h), d_dot, atol=1e-7)


# --- blended start -------------------------------------------------------------------------
def test_blend_function_properties():
    T = 1.5
    b, bd = blend_quintic(np.array([0.0, T, 2 * T]), T)
    np.testing.assert_array_equal(b, [0.0, 1.0, 1.0])
    np.testing.assert_array_equal(bd, [0.0, 0.0, 0.0])
    t, h = np.linspace(0.05, T - 0.05, 50), 1e-6
    _, bd = blend_quintic(t, T)
    bp, _ = blend_quintic(t + h, T)
    bm, _ = blend_quintic(t - h, T)
    np.testing.assert_allclose(bd, (bp - bm) / (2 * h), atol=1e-8)
    with pytest.raises(ValueError, match="blend_time must be a positive duration"):
        blend_quintic(t, 0.0)


def test_blended_start_is_at_rest_and_joins_exact_law():
    T = 1.0
    L, Ld = appendix_leg_lengths(0.0, start="blended", blend_time=T)
    np.testing.assert_allclose(L[0], L0, atol=1e-12)
    np.testing.assert_array_equal(Ld[0], 0.0)
    # Zero initial acceleration: L̇(δ)/δ -> 0 (it is O(δ) because b'' (0) = 0 too).
    for delta in (1e-3, 1e-4):
        _, Ld_small = appendix_leg_lengths(delta, start="blended", blend_time=T)
        assert np.abs(Ld_small).max() / delta < 10 * delta
    # Identical to the exact law from blend_time on.
    t = np.linspace(T, T_END, 2001)
    Le, Lde = appendix_leg_lengths(t)
    Lb, Ldb = appendix_leg_lengths(t, start="blended", blend_time=T)
    np.testing.assert_array_equal(Lb, Le)
    np.testing.assert_array_equal(Ldb, Lde)
    # Before blend_time the two differ (the ramp is active).
    Le, _ = appendix_leg_lengths(0.5)
    Lb, _ = appendix_leg_lengths(0.5, start="blended", blend_time=T)
    assert np.abs(Le - Lb).max() > 1e-3


def test_blend_is_c2_at_blend_time():
    T, d = 1.0, 1e-4
    t = np.array([T - 2 * d, T - d, T, T + d, T + 2 * d])
    L, Ld = appendix_leg_lengths(t, start="blended", blend_time=T)
    # C0 and C1: one-sided values meet (within O(d) of smooth variation).
    assert np.all(np.abs(L[3] - L[1]) <= 2 * d * np.abs(Ld[1:4]).max(axis=0) * 1.01)
    np.testing.assert_allclose(Ld[1], Ld[3], atol=10 * d)
    # C2: left and right one-sided second-order accelerations agree to O(d²).
    acc_left = (3 * Ld[2] - 4 * Ld[1] + Ld[0]) / (2 * d)
    acc_right = (-3 * Ld[2] + 4 * Ld[3] - Ld[4]) / (2 * d)
    np.testing.assert_allclose(acc_left, acc_right, atol=1e-5)
    assert np.abs(acc_right).max() > 0.05  # acceleration is not trivially zero there


# --- platform outputs ----------------------------------------------------------------------
@pytest.mark.parametrize("start", ["exact", "blended"])
def test_platform_quaternion_matches_rotation(start):
    p_G, q = appendix_platform_outputs(T_GRID, start=start)
    p_ref, R = appendix_pose(T_GRID, start=start)
    np.testing.assert_array_equal(p_G, p_ref)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    assert q[:, 0].min() > 0.0
    np.testing.assert_allclose(_quat_to_matrix(q), R, rtol=0, atol=1e-14)


# --- input validation ----------------------------------------------------------------------
def test_rejects_times_outside_law_and_bad_start():
    with pytest.raises(ValueError, match=r"0 <= t <= 20"):
        appendix_leg_lengths([0.0, 20.5])
    with pytest.raises(ValueError, match="start must be 'exact' or 'blended'"):
        appendix_pose(1.0, start="smooth")  # type: ignore[arg-type]
    # Float accumulation just past the end is accepted and clipped.
    L, _ = appendix_leg_lengths(2000 * 0.01 + 1e-12)
    np.testing.assert_array_equal(L, appendix_leg_lengths(T_END)[0])


# --- command table -------------------------------------------------------------------------
def test_command_table_roundtrip(tmp_path: Path):
    t = np.linspace(0.0, 2.0, 201)
    L, Ld = appendix_leg_lengths(t, start="blended")
    path = tmp_path / "cmd.csv"
    write_command_table(path, t, L, Ld)
    header = path.read_text().splitlines()[0]
    assert header == "t,leg1,leg2,leg3,leg4,leg5,leg6," + ",".join(
        f"leg{i}_rate" for i in range(1, 7)
    )
    t2, L2, Ld2, names = read_command_table(path)
    assert names == [f"leg{i}" for i in range(1, 7)]
    np.testing.assert_array_equal(t2, t)
    np.testing.assert_array_equal(L2, L)
    assert Ld2 is not None
    np.testing.assert_array_equal(Ld2, Ld)


def test_command_table_without_rates_and_custom_names(tmp_path: Path):
    t = np.array([0.0, 0.1])
    L = np.array([[1.0, 2.0], [1.5, 2.5]])
    path = tmp_path / "cmd2.csv"
    write_command_table(path, t, L, names=["left", "right"])
    t2, L2, Ld2, names = read_command_table(path)
    assert names == ["left", "right"] and Ld2 is None
    np.testing.assert_array_equal(L2, L)
    with pytest.raises(ValueError, match=r"lengths must have shape \(len\(t\), len\(names\)\)"):
        write_command_table(path, t, L)  # default names are six
    with pytest.raises(ValueError, match="without commas"):
        write_command_table(path, t, L, names=["a,b", "c"])
