"""Stewart platform of Siqueira & Coda (2019), appendix Eqs. 52-60: geometry and leg commands.

The paper drives a 6-3 Stewart platform by imposing the reference length of each flexible
actuator. The appendix gives the commanded motion of the platform centroid G (Eqs. 52-54), two
rotation-angle histories (Eqs. 58-59), the displacements of the platform vertices A, B, C
(Eqs. 55-57) and the leg lengths (Eq. 60). This module evaluates that command, vectorized over a
time array, with no dependency beyond numpy.

Conventions (derived from the paper, see ``appendix_vertex_displacements_literal``)
-------------------------------------------------------------------------------
* Axes: z vertical (up), base plane z = 0; the platform lies in a horizontal plane, its centroid
  starts at ``p_G0 = (0, 0, H)``; vertex A points along +y.
* Rotations are active and right-handed: ``R_z(γ) = [[cγ, -sγ, 0], [sγ, cγ, 0], [0, 0, 1]]`` and
  ``R_x(β) = [[1, 0, 0], [0, cβ, -sβ], [0, sβ, cβ]]``. With these, Eqs. 55 and 57 (all terms) and
  Eq. 56 (β terms and the x γ-term) are exactly ``R X_rel - X_rel``.
* The platform orientation is ``R = R_z(γ) R_x(β)``; only one angle is non-zero at a time, so the
  order does not matter for the appendix law (inside a blended switch both are, and this order is
  the definition).
* Eq. 56's y γ-term reads ``+ℓ/2 sin γ``; the rigid rotation of ``B_rel = (-ℓ/2, -h/3, 0)`` gives
  ``-ℓ/2 sin γ``. The paper's Eq. 56 would stretch the platform edges, so the rigid rotation is
  used everywhere (SPEC §6.1); the literal equations are kept only for comparison.
* Piecewise laws switch at t = 10 s (ψ = 2π, γ → β). Values are continuous there; velocities are
  not (the radius rate drops by R_max/10 = 0.03 m/s and the angular velocity jumps from
  -π²/40 about z to +π²/60 about x; leg rates jump by up to 0.13 m/s). At exactly t = 10 s the
  rates of the first branch are returned.
* The law is defined for 0 ≤ t ≤ 20 s (Eq. 54); times outside that interval are rejected. It ends
  in motion (the command program holds the final lengths after 20 s, a rate jump outside the law).

Start-up
--------
The exact law starts with non-zero velocity from a platform at rest:
``ż_G(0) = (h0/2)(2π/5) = 0.18850 m/s``, ``ẏ_G(0) = d/dt[R(ψ) cos ψ](0) = R_max/10 = 0.03 m/s``,
``ẋ_G(0) = 0``, ``γ̇(0) = π²/40 = 0.24674 rad/s``. The leg rates at t = 0 are therefore non-zero
(0.22325, 0.13534, 0.21524, 0.14336, 0.23127, 0.12732 m/s for legs 1-6, default geometry).
``start="blended"`` multiplies the motion (``d_G``, γ, β) by the quintic
``b(τ) = 10τ³ - 15τ⁴ + 6τ⁵``, ``τ = t / blend_time``, so legs start at rest with zero acceleration
and the command equals the exact law for ``t ≥ blend_time``.

Branch switch
-------------
``switch_blend = T > 0`` replaces the switch by a C² (or smoother) blend of the two branches over
``[10 − T/2, 10 + T/2]``: with the ramp ``s(t) = b((t − 10 + T/2)/T)``, the spiral radius is
``(1 − s) R₁(ψ) + s R_max``, and the angles ``γ = (1 − s) γ₁(t)``, ``β = s β₂(t)`` (each branch
continued analytically through the window; both rotations act inside it, ``R = R_z(γ) R_x(β)``).
Pose, velocity and acceleration are continuous, the law is unchanged outside the window, and the
blend departs from the exact law by at most 2.2 mm in leg length and 0.53 mm in centroid position
(T = 0.5 s, quintic; both ∝ T), with leg accelerations up to 0.97 m/s² (∝ 1/T). With the quintic
the jerk still jumps at the window ends.

Blend continuity
----------------
``blend_continuity = k`` (2, 3, 4) selects the ramp of both blends: b' ∝ τ^k (1 − τ)^k (k = 2 is
the quintic above, 4 the nonic ``126τ⁵ − 420τ⁶ + 540τ⁷ − 315τ⁸ + 70τ⁹``). A blend of class C^k
has its first jump in the (k+1)-th derivative, which rings a structural mode of circular frequency ω
with an amplitude ∝ jump/ω^(k+1): for the Stewart legs (first modes 107–135 Hz) the quintic's
jerk jumps ring at ~1e-8 m (measured), the nonic's at ~1e-11 m (estimated), below the time error
of any Δt ≤ 4 ms (docs/benchmarks/stewart.md).

Leg-length range over 0-20 s (default geometry, L0 = 1.0513 m, sampled every 1 ms)
---------------------------------------------------------------------------------
* exact law:   min 0.72163 m (leg 5, t ≈ 13.9 s), max 1.54214 m (leg 2, t ≈ 16.2 s), i.e.
  ΔL from -0.32967 m to +0.49084 m (stroke 0.82 m); max |L̇| = 0.3152 m/s.
* blended law (blend_time = 1 s): same length extremes (they occur after t = 1 s);
  max |L̇| = 0.3492 m/s, reached during the ramp, which compresses the start into 1 s.
* the shipped scenes' law (blended start 1 s, ``switch_blend`` 0.5 s, ``blend_continuity`` 4): same
  extremes; max |L̇| = 0.4060 m/s (t ≈ 0.58 s), max |L̈| = 1.47 m/s² (t ≈ 0.39 s), 1.27 m/s² in the
  switch window.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from os import PathLike
from typing import Literal, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "H0",
    "R_MAX",
    "T_END",
    "T_SWITCH",
    "VERTEX_NAMES",
    "StewartGeometry",
    "StewartLayout",
    "appendix_leg_lengths",
    "appendix_platform_outputs",
    "appendix_pose",
    "appendix_vertex_displacements",
    "appendix_vertex_displacements_literal",
    "appendix_vertex_positions",
    "blend_quintic",
    "smoothstep",
    "switch_weight",
    "default_leg_names",
    "read_command_table",
    "rotation_x",
    "rotation_z",
    "write_command_table",
]

FloatArray = NDArray[np.float64]
StartMode = Literal["exact", "blended"]

H0 = 0.30
"""Peak-to-peak amplitude of the vertical centroid motion, h0 in Eq. 52 [m]."""
R_MAX = 0.30
"""Final radius of the horizontal centroid spiral, R_max in Eq. 53 [m]."""
T_SWITCH = 10.0
"""Time at which ψ reaches 2π and the rotation switches from γ (about z) to β (about x) [s]."""
T_END = 20.0
"""End of the appendix law, Eq. 54 [s]."""

# Tolerance on the time window, so that float accumulation (e.g. ``k * dt`` reaching
# 20.000000000000004) is not rejected; such times are clipped to the window.
_T_TOL = 1e-9

VERTEX_NAMES: tuple[str, str, str] = ("A", "B", "C")


# ----------------------------------------------------------------------------------------------
# Geometry
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StewartLayout:
    """Arrays describing the initial configuration of the 6-3 platform.

    Attributes
    ----------
    base_points : ndarray, shape (6, 3)
        Base attachment point ``p_i`` of each leg [m].
    vertices0 : ndarray, shape (3, 3)
        Initial positions ``p_X0`` of the platform vertices A, B, C [m].
    leg_vertex : ndarray of int64, shape (6,)
        Index (0 = A, 1 = B, 2 = C) of the platform vertex each leg connects to.
    lengths0 : ndarray, shape (6,)
        Initial leg lengths ``L_i0`` [m]; all equal ``StewartGeometry.leg_length``.
    """

    base_points: FloatArray
    vertices0: FloatArray
    leg_vertex: NDArray[np.int64]
    lengths0: FloatArray


@dataclass(frozen=True)
class StewartGeometry:
    """Geometry of the appendix Stewart platform (6-3: two legs per platform vertex).

    The base points are not given in the paper (SPEC §6.1 [G]); this choice keeps all six legs
    at ``leg_length``: each platform vertex's vertical projection is flanked by two base points
    at height 0, offset by ``±d`` perpendicular to the line from the base centre to that
    projection, with ``H² + d² = L0²``.

    Parameters
    ----------
    side : float
        Side ℓ of the equilateral platform triangle A-B-C [m].
    height : float
        Initial height H of the platform centroid G above the base plane [m].
    leg_length : float
        Initial length L0 of every leg [m]; must exceed ``height``.
    """

    side: float = 1.0
    height: float = 1.0
    leg_length: float = 1.0513

    def __post_init__(self) -> None:
        if not (math.isfinite(self.side) and self.side > 0.0):
            raise ValueError(
                f"StewartGeometry.side must be a positive length in m, got {self.side!r}"
            )
        if not (math.isfinite(self.height) and self.height > 0.0):
            raise ValueError(
                f"StewartGeometry.height must be a positive length in m, got {self.height!r}"
            )
        if not (math.isfinite(self.leg_length) and self.leg_length > self.height):
            raise ValueError(
                f"StewartGeometry.leg_length must exceed height (H² + d² = L0² needs d > 0), "
                f"got leg_length={self.leg_length!r}, height={self.height!r}"
            )

    @classmethod
    def default(cls) -> StewartGeometry:
        """Paper values ℓ = 1.0 m, L0 = 1.0513 m and the chosen H = 1.0 m (d ≈ 0.3244 m)."""
        return cls()

    @property
    def triangle_height(self) -> float:
        """Height h = (√3/2) ℓ of the platform triangle [m]."""
        return math.sqrt(3.0) / 2.0 * self.side

    @property
    def base_offset(self) -> float:
        """Tangential offset d = √(L0² − H²) of each base point from the vertex projection [m]."""
        return math.sqrt(self.leg_length**2 - self.height**2)

    def vertex_offsets(self) -> FloatArray:
        """Platform vertices A, B, C relative to the centroid G, shape (3, 3) [m]."""
        h, half = self.triangle_height, 0.5 * self.side
        return np.array(
            [[0.0, 2.0 * h / 3.0, 0.0], [-half, -h / 3.0, 0.0], [half, -h / 3.0, 0.0]]
        )

    def centroid0(self) -> FloatArray:
        """Initial centroid position p_G0 = (0, 0, H), shape (3,) [m]."""
        return np.array([0.0, 0.0, self.height])

    def layout(self) -> StewartLayout:
        """Base points, initial vertex positions, leg→vertex map and initial leg lengths."""
        offsets = self.vertex_offsets()  # (3, 3)
        vertices0 = self.centroid0() + offsets  # (3, 3)
        leg_vertex = np.array([0, 0, 1, 1, 2, 2], dtype=np.int64)
        radial = offsets[:, :2] / np.linalg.norm(offsets[:, :2], axis=1, keepdims=True)  # (3, 2)
        # Counter-clockwise tangent e_z × radial: the leg pair straddles the vertex projection
        # symmetrically, so both legs have length √(H² + d²) = L0.
        tangent = np.column_stack([-radial[:, 1], radial[:, 0], np.zeros(3)])  # (3, 3)
        sign = np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0])[:, None]  # (6, 1)
        base = offsets[leg_vertex] + sign * self.base_offset * tangent[leg_vertex]  # (6, 3)
        base[:, 2] = 0.0
        lengths0 = np.linalg.norm(vertices0[leg_vertex] - base, axis=1)  # (6,)
        return StewartLayout(base, vertices0, leg_vertex, lengths0)


def default_leg_names() -> list[str]:
    """Actuator names ``leg1`` … ``leg6`` in leg order."""
    return [f"leg{i}" for i in range(1, 7)]


# ----------------------------------------------------------------------------------------------
# Rotations and blending
# ----------------------------------------------------------------------------------------------
def rotation_z(angle: ArrayLike) -> FloatArray:
    """Active right-handed rotation about z, shape (n, 3, 3), for angles γ of shape (n,) [rad]."""
    a = np.atleast_1d(np.asarray(angle, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1] = c, -s
    R[..., 1, 0], R[..., 1, 1] = s, c
    R[..., 2, 2] = 1.0
    return R


def rotation_x(angle: ArrayLike) -> FloatArray:
    """Active right-handed rotation about x, shape (n, 3, 3), for angles β of shape (n,) [rad]."""
    a = np.atleast_1d(np.asarray(angle, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0] = 1.0
    R[..., 1, 1], R[..., 1, 2] = c, -s
    R[..., 2, 1], R[..., 2, 2] = s, c
    return R


def _rotation_z_rate(angle: FloatArray, rate: FloatArray) -> FloatArray:
    """d/dt R_z(γ(t)) = γ̇ R_z'(γ), shape (n, 3, 3) [1/s]."""
    c, s = np.cos(angle), np.sin(angle)
    dR = np.zeros(angle.shape + (3, 3))
    dR[..., 0, 0], dR[..., 0, 1] = -s * rate, -c * rate
    dR[..., 1, 0], dR[..., 1, 1] = c * rate, -s * rate
    return dR


def _rotation_x_rate(angle: FloatArray, rate: FloatArray) -> FloatArray:
    """d/dt R_x(β(t)) = β̇ R_x'(β), shape (n, 3, 3) [1/s]."""
    c, s = np.cos(angle), np.sin(angle)
    dR = np.zeros(angle.shape + (3, 3))
    dR[..., 1, 1], dR[..., 1, 2] = -s * rate, -c * rate
    dR[..., 2, 1], dR[..., 2, 2] = c * rate, -s * rate
    return dR


def blend_quintic(t: ArrayLike, blend_time: float) -> tuple[FloatArray, FloatArray]:
    """C² start-up ramp b(t) = 10τ³ − 15τ⁴ + 6τ⁵, τ = clip(t / blend_time, 0, 1).

    b, b' and b'' vanish at τ = 0; b = 1 and b' = b'' = 0 at τ = 1, so a motion multiplied by b
    starts at rest and joins the unblended motion with continuous acceleration.

    Parameters
    ----------
    t : array_like, shape (n,)
        Time [s].
    blend_time : float
        Duration of the ramp [s], > 0.

    Returns
    -------
    b : ndarray, shape (n,)
        Ramp value [-].
    b_dot : ndarray, shape (n,)
        Its time derivative [1/s].
    """
    if not (math.isfinite(blend_time) and blend_time > 0.0):
        raise ValueError(f"blend_time must be a positive duration in s, got {blend_time!r}")
    tau = np.clip(np.asarray(t, dtype=np.float64) / blend_time, 0.0, 1.0)
    b = tau**3 * (10.0 + tau * (-15.0 + 6.0 * tau))
    b_dot = 30.0 * tau**2 * (1.0 - tau) ** 2 / blend_time
    return b, b_dot


def smoothstep(t: ArrayLike, duration: float, continuity: int = 2) -> tuple[FloatArray, FloatArray]:
    """C^k ramp from 0 to 1 over [0, duration]: b' ∝ τ^k (1 − τ)^k, so b' … b^(k) vanish at both
    ends (k = 2: the quintic of :func:`blend_quintic`; 3: septic; 4: nonic), τ = clip(t/duration).

    Returns b (n,) [-] and its time derivative (n,) [1/s]. A motion blended with a C^k ramp has its
    first jump in the (k+1)-th derivative: a structural mode ω is excited ∝ ω^−(k+1).
    """
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"blend duration must be a positive duration in s, got {duration!r}")
    if continuity not in (2, 3, 4):
        raise ValueError(f"blend continuity must be 2, 3 or 4, got {continuity!r}")
    k = continuity
    tau = np.clip(np.asarray(t, dtype=np.float64) / duration, 0.0, 1.0)
    c = math.factorial(2 * k + 1) / math.factorial(k) ** 2
    # b(τ) = c ∫₀^τ u^k (1 − u)^k du = c Σ_j (−1)^j C(k, j) τ^(k+j+1) / (k+j+1)
    b = np.zeros_like(tau)
    for j in range(k + 1):
        b += (-1) ** j * math.comb(k, j) * tau ** (k + j + 1) / (k + j + 1)
    b *= c
    b[tau >= 1.0] = 1.0             # exactly the end value (the sum leaves ~1e-15)
    b_dot = c * tau**k * (1.0 - tau) ** k / duration
    return b, b_dot


# ----------------------------------------------------------------------------------------------
# The appendix law (Eqs. 52-54, 58-59) and its exact time derivative
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Motion:
    """Centroid displacement and rotation angles with their rates, all over n times."""

    d: FloatArray  # (n, 3) centroid displacement d_G [m]
    d_dot: FloatArray  # (n, 3) [m/s]
    gamma: FloatArray  # (n,) rotation about z [rad]
    gamma_dot: FloatArray  # (n,) [rad/s]
    beta: FloatArray  # (n,) rotation about x [rad]
    beta_dot: FloatArray  # (n,) [rad/s]


def _as_time(t: ArrayLike) -> FloatArray:
    """Validate and flatten a time input to shape (n,), clipped to [0, T_END] [s]."""
    arr = np.atleast_1d(np.asarray(t, dtype=np.float64))
    if arr.ndim != 1:
        raise ValueError(f"time must be a scalar or a 1-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("time contains non-finite values")
    if arr.size and (arr.min() < -_T_TOL or arr.max() > T_END + _T_TOL):
        raise ValueError(
            f"the appendix law is defined for 0 <= t <= {T_END} s (Eq. 54), got times in "
            f"[{float(arr.min()):g}, {float(arr.max()):g}] s"
        )
    return np.clip(arr, 0.0, T_END)


def _check_switch_blend(switch_blend: float) -> None:
    if not (math.isfinite(switch_blend) and 0.0 <= switch_blend <= 2.0 * (T_END - T_SWITCH)):
        raise ValueError(f"switch_blend must be a duration in [0, {2.0 * (T_END - T_SWITCH):g}] s "
                         f"(0: exact switch), got {switch_blend!r}")


def switch_weight(t: ArrayLike, switch_blend: float, continuity: int = 2) -> tuple[FloatArray, FloatArray]:
    """Weight s(t) of the second branch and its rate: the C^k ramp (:func:`smoothstep`, k =
    ``continuity``) over [10 − T/2, 10 + T/2] for ``switch_blend = T > 0``; the step at t = 10 s
    (first branch at t = 10 s) for T = 0."""
    _check_switch_blend(switch_blend)
    tt = np.asarray(t, dtype=np.float64)
    if switch_blend == 0.0:
        return (tt > T_SWITCH).astype(np.float64), np.zeros_like(tt)
    return smoothstep(tt - (T_SWITCH - 0.5 * switch_blend), switch_blend, continuity)


def _centroid_law(t: FloatArray, switch_blend: float = 0.0, continuity: int = 2) -> tuple[FloatArray, FloatArray]:
    """Eqs. 52-54: centroid displacement d_G (n, 3) [m] and its rate (n, 3) [m/s]."""
    psi_dot = math.pi / 5.0
    psi = psi_dot * t
    # Eq. 53 branch ψ ≤ 2π ⇔ t ≤ T_SWITCH; tested on t so both laws switch at the same sample.
    w, w_dot = switch_weight(t, switch_blend, continuity)
    r1 = R_MAX * psi / (2.0 * math.pi)
    r1_dot = R_MAX * psi_dot / (2.0 * math.pi)
    radius = (1.0 - w) * r1 + w * R_MAX
    radius_dot = (1.0 - w) * r1_dot + w_dot * (R_MAX - r1)
    s, c = np.sin(psi), np.cos(psi)
    omega_z = 2.0 * math.pi / 5.0
    d = np.column_stack([-radius * s, radius * c, 0.5 * H0 * np.sin(omega_z * t)])
    d_dot = np.column_stack(
        [
            -(radius_dot * s + radius * c * psi_dot),
            radius_dot * c - radius * s * psi_dot,
            0.5 * H0 * omega_z * np.cos(omega_z * t),
        ]
    )
    return d, d_dot


def _angle_law(t: FloatArray, switch_blend: float = 0.0,
               continuity: int = 2) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Eqs. 58-59: γ, γ̇ (about z, 0-10 s) and β, β̇ (about x, 10-20 s) [rad, rad/s]."""
    w = math.pi / 10.0
    sw, sw_dot = switch_weight(t, switch_blend, continuity)
    s, c = np.sin(w * t), np.cos(w * t)
    g1, g1_dot = math.pi / 4.0 * s, math.pi / 4.0 * w * c
    b2, b2_dot = -math.pi / 6.0 * s, -math.pi / 6.0 * w * c
    gamma = (1.0 - sw) * g1
    gamma_dot = (1.0 - sw) * g1_dot - sw_dot * g1
    beta = sw * b2
    beta_dot = sw * b2_dot + sw_dot * b2
    return gamma, gamma_dot, beta, beta_dot


def _commanded_motion(t: FloatArray, start: StartMode, blend_time: float, switch_blend: float = 0.0,
                      continuity: int = 2) -> _Motion:
    """Exact law, or the law with d_G, γ, β scaled by the C^k ramp b(t) (product rule for rates);
    ``switch_blend`` > 0 blends the t = 10 s branch switch (see the module docstring); both blends
    are C^k, k = ``continuity``."""
    if continuity not in (2, 3, 4):
        raise ValueError(f"blend_continuity must be 2, 3 or 4, got {continuity!r}")
    d, d_dot = _centroid_law(t, switch_blend, continuity)
    gamma, gamma_dot, beta, beta_dot = _angle_law(t, switch_blend, continuity)
    if start == "exact":
        return _Motion(d, d_dot, gamma, gamma_dot, beta, beta_dot)
    if start != "blended":
        raise ValueError(f"start must be 'exact' or 'blended', got {start!r}")
    b, b_dot = (blend_quintic(t, blend_time) if continuity == 2
                else smoothstep(t, blend_time, continuity))
    return _Motion(
        d * b[:, None],
        d_dot * b[:, None] + d * b_dot[:, None],
        gamma * b,
        gamma_dot * b + gamma * b_dot,
        beta * b,
        beta_dot * b + beta * b_dot,
    )


def _orientation(m: _Motion) -> tuple[FloatArray, FloatArray]:
    """Platform rotation R = R_z(γ) R_x(β) (n, 3, 3) and its time derivative (n, 3, 3)."""
    Rz, Rx = rotation_z(m.gamma), rotation_x(m.beta)
    R = Rz @ Rx
    R_dot = _rotation_z_rate(m.gamma, m.gamma_dot) @ Rx + Rz @ _rotation_x_rate(m.beta, m.beta_dot)
    return R, R_dot


# ----------------------------------------------------------------------------------------------
# Public commands
# ----------------------------------------------------------------------------------------------
def appendix_pose(
    t: ArrayLike,
    geometry: StewartGeometry | None = None,
    *,
    start: StartMode = "exact",
    blend_time: float = 1.0,
    switch_blend: float = 0.0,
    blend_continuity: int = 2,
) -> tuple[FloatArray, FloatArray]:
    """Commanded platform pose: centroid position and rotation matrix (Eqs. 52-54, 58-59).

    Parameters
    ----------
    t : array_like, shape (n,) or scalar
        Time, 0 ≤ t ≤ 20 [s].
    geometry : StewartGeometry, optional
        Platform geometry (only H enters); default ``StewartGeometry.default()``.
    start : {"exact", "blended"}
        ``"blended"`` ramps the motion in over ``blend_time`` (see ``blend_quintic``).
    blend_time : float
        Ramp duration for ``start="blended"`` [s].
    switch_blend : float
        Duration T of the blend of the t = 10 s branch switch over [10 − T/2, 10 + T/2] [s];
        0 (default) keeps the exact switch.
    blend_continuity : {2, 3, 4}
        Continuity C^k of both blends (start and switch); 2 (default) is the quintic.

    Returns
    -------
    p_G : ndarray, shape (n, 3)
        Centroid position p_G0 + d_G [m].
    R : ndarray, shape (n, 3, 3)
        Platform rotation R_z(γ) R_x(β) (maps body offsets to world) [-].
    """
    geometry = geometry or StewartGeometry.default()
    m = _commanded_motion(_as_time(t), start, blend_time, switch_blend, blend_continuity)
    R, _ = _orientation(m)
    return geometry.centroid0() + m.d, R


def appendix_vertex_positions(
    t: ArrayLike,
    geometry: StewartGeometry | None = None,
    *,
    start: StartMode = "exact",
    blend_time: float = 1.0,
    switch_blend: float = 0.0,
    blend_continuity: int = 2,
) -> tuple[FloatArray, FloatArray]:
    """Commanded positions and velocities of the vertices A, B, C under the rigid motion.

    ``p_X = p_G0 + d_G + R X_rel`` and ``ṗ_X = ḋ_G + Ṙ X_rel`` (exact derivative, no differencing).

    Parameters
    ----------
    t, geometry, start, blend_time, switch_blend, blend_continuity
        As in ``appendix_pose``.

    Returns
    -------
    p : ndarray, shape (n, 3, 3)
        Vertex positions, axes (time, vertex A/B/C, xyz) [m].
    v : ndarray, shape (n, 3, 3)
        Vertex velocities, same axes [m/s].
    """
    geometry = geometry or StewartGeometry.default()
    m = _commanded_motion(_as_time(t), start, blend_time, switch_blend, blend_continuity)
    R, R_dot = _orientation(m)
    offsets = geometry.vertex_offsets()  # (3, 3) rows = vertices
    p = geometry.centroid0() + m.d[:, None, :] + np.einsum("nij,vj->nvi", R, offsets)
    v = m.d_dot[:, None, :] + np.einsum("nij,vj->nvi", R_dot, offsets)
    return p, v


def appendix_vertex_displacements(
    t: ArrayLike,
    geometry: StewartGeometry | None = None,
    *,
    start: StartMode = "exact",
    blend_time: float = 1.0,
    switch_blend: float = 0.0,
    blend_continuity: int = 2,
) -> FloatArray:
    """Rigid-motion vertex displacements d_X = d_G + (R − I) X_rel, shape (n, 3, 3) [m].

    This is what Eqs. 55-57 intend; see ``appendix_vertex_displacements_literal`` for the
    difference in Eq. 56.
    """
    geometry = geometry or StewartGeometry.default()
    p, _ = appendix_vertex_positions(t, geometry, start=start, blend_time=blend_time,
                                     switch_blend=switch_blend, blend_continuity=blend_continuity)
    return p - (geometry.centroid0() + geometry.vertex_offsets())


def appendix_vertex_displacements_literal(
    t: ArrayLike, geometry: StewartGeometry | None = None
) -> FloatArray:
    """Vertex displacements exactly as printed in Eqs. 55-57 (exact law, no blending).

    Kept to document the paper: A (Eq. 55) and C (Eq. 57) equal the rigid rotation with the
    right-handed ``R_x(β)``, ``R_z(γ)`` of this module; B (Eq. 56) has ``+ℓ/2 sin γ`` in its
    y-term where the rigid rotation of ``B_rel = (−ℓ/2, −h/3, 0)`` gives ``−ℓ/2 sin γ``. With
    the literal B the edge lengths |AB| and |BC| change with γ, so it is not used for commands.

    Parameters
    ----------
    t : array_like, shape (n,) or scalar
        Time, 0 ≤ t ≤ 20 [s].
    geometry : StewartGeometry, optional
        Supplies ℓ and h; default ``StewartGeometry.default()``.

    Returns
    -------
    d : ndarray, shape (n, 3, 3)
        Displacements of A, B, C, axes (time, vertex, xyz) [m].
    """
    geometry = geometry or StewartGeometry.default()
    tt = _as_time(t)
    d_G, _ = _centroid_law(tt)
    gamma, _, beta, _ = _angle_law(tt)
    ell, h = geometry.side, geometry.triangle_height
    cb, sb, cg, sg = np.cos(beta), np.sin(beta), np.cos(gamma), np.sin(gamma)
    zero = np.zeros_like(tt)
    beta_a = np.column_stack([zero, 2 * h / 3 * (cb - 1), 2 * h / 3 * sb])
    gamma_a = np.column_stack([-2 * h / 3 * sg, 2 * h / 3 * (cg - 1), zero])
    beta_bc = np.column_stack([zero, h / 3 * (1 - cb), -h / 3 * sb])
    gamma_b = np.column_stack(
        [-ell / 2 * cg + h / 3 * sg + ell / 2, -h / 3 * cg + ell / 2 * sg + h / 3, zero]
    )
    gamma_c = np.column_stack(
        [ell / 2 * cg + h / 3 * sg - ell / 2, -h / 3 * cg + ell / 2 * sg + h / 3, zero]
    )
    return np.stack(
        [d_G + beta_a + gamma_a, d_G + beta_bc + gamma_b, d_G + beta_bc + gamma_c], axis=1
    )


def appendix_leg_lengths(
    t: ArrayLike,
    geometry: StewartGeometry | None = None,
    *,
    start: StartMode = "exact",
    blend_time: float = 1.0,
    switch_blend: float = 0.0,
    blend_continuity: int = 2,
) -> tuple[FloatArray, FloatArray]:
    """Commanded absolute leg lengths L_i(t) (Eq. 60) and their exact time derivatives.

    ``L_i = ‖p_X0 + d_X(t) − p_i‖`` with the rigid vertex motion, so ΔL_i = L_i − L_i0.
    ``L̇_i = (r_i · ṙ_i) / L_i`` with ``r_i = p_X − p_i``; ``ṙ_i`` comes from the analytic
    derivative of the pose.

    Parameters
    ----------
    t : array_like, shape (n,) or scalar
        Time, 0 ≤ t ≤ 20 [s].
    geometry : StewartGeometry, optional
        Default ``StewartGeometry.default()``.
    start : {"exact", "blended"}
        ``"exact"``: Eqs. 52-60 as printed (non-zero leg rates at t = 0). ``"blended"``: motion
        scaled by the C² ramp, zero rates at t = 0 and identical to ``"exact"`` for
        t ≥ ``blend_time``.
    blend_time : float
        Ramp duration for ``start="blended"`` [s].
    switch_blend : float
        Duration of the blend of the t = 10 s branch switch [s]; 0: exact switch (rate jump).
    blend_continuity : {2, 3, 4}
        Continuity C^k of both blends (start and switch); 2 (default) is the quintic.

    Returns
    -------
    lengths : ndarray, shape (n, 6)
        Leg lengths [m].
    rates : ndarray, shape (n, 6)
        Leg length rates [m/s].
    """
    geometry = geometry or StewartGeometry.default()
    layout = geometry.layout()
    p, v = appendix_vertex_positions(t, geometry, start=start, blend_time=blend_time,
                                     switch_blend=switch_blend, blend_continuity=blend_continuity)
    r = p[:, layout.leg_vertex, :] - layout.base_points  # (n, 6, 3)
    lengths = np.linalg.norm(r, axis=2)  # (n, 6)
    rates = np.einsum("nlk,nlk->nl", r, v[:, layout.leg_vertex, :]) / lengths
    return lengths, rates


def appendix_platform_outputs(
    t: ArrayLike,
    geometry: StewartGeometry | None = None,
    *,
    start: StartMode = "exact",
    blend_time: float = 1.0,
    switch_blend: float = 0.0,
    blend_continuity: int = 2,
) -> tuple[FloatArray, FloatArray]:
    """Commanded centroid position and orientation quaternion, for pose-tracking comparisons.

    The quaternion is ``q_z(γ) ⊗ q_x(β)`` (same rotation as ``appendix_pose``), scalar first,
    with w ≥ 0 over the whole law since |γ|, |β| < π.

    Parameters
    ----------
    t, geometry, start, blend_time, switch_blend, blend_continuity
        As in ``appendix_pose``.

    Returns
    -------
    p_G : ndarray, shape (n, 3)
        Centroid position [m].
    quat : ndarray, shape (n, 4)
        Unit quaternion (w, x, y, z) [-].
    """
    geometry = geometry or StewartGeometry.default()
    m = _commanded_motion(_as_time(t), start, blend_time, switch_blend, blend_continuity)
    cg, sg = np.cos(0.5 * m.gamma), np.sin(0.5 * m.gamma)
    cb, sb = np.cos(0.5 * m.beta), np.sin(0.5 * m.beta)
    quat = np.column_stack([cg * cb, cg * sb, sg * sb, sg * cb])
    return geometry.centroid0() + m.d, quat


# ----------------------------------------------------------------------------------------------
# Command table I/O
# ----------------------------------------------------------------------------------------------
def write_command_table(
    path: str | PathLike[str],
    t: ArrayLike,
    lengths: ArrayLike,
    rates: ArrayLike | None = None,
    names: Sequence[str] | None = None,
) -> None:
    """Write a leg-command table as CSV.

    Header ``t,<name1>,…,<nameM>`` followed, when ``rates`` is given, by
    ``<name1>_rate,…,<nameM>_rate``; one row per time. Values are written with 17 significant
    digits so that ``read_command_table`` recovers them bit for bit. Units: t [s], lengths [m],
    rates [m/s].

    Parameters
    ----------
    path : str or path-like
        Output file (overwritten).
    t : array_like, shape (n,)
        Time [s].
    lengths : array_like, shape (n, m)
        Actuator reference lengths [m].
    rates : array_like, shape (n, m), optional
        Their time derivatives [m/s].
    names : sequence of str, optional
        m actuator names; default ``leg1`` … ``leg6``.
    """
    tt = np.atleast_1d(np.asarray(t, dtype=np.float64))
    L = np.asarray(lengths, dtype=np.float64)
    names = list(names) if names is not None else default_leg_names()
    if tt.ndim != 1 or L.shape != (tt.size, len(names)):
        raise ValueError(
            f"lengths must have shape (len(t), len(names)) = ({tt.size}, {len(names)}), "
            f"got {L.shape}"
        )
    bad = [n for n in names if not n or any(ch in n for ch in ',"\n\r')]
    if bad or len(set(names)) != len(names):
        raise ValueError(f"actuator names must be unique, non-empty, without commas: {names!r}")
    header = ["t", *names]
    columns = [tt[:, None], L]
    if rates is not None:
        Ld = np.asarray(rates, dtype=np.float64)
        if Ld.shape != L.shape:
            raise ValueError(f"rates must have the shape of lengths {L.shape}, got {Ld.shape}")
        header += [f"{n}_rate" for n in names]
        columns.append(Ld)
    table = np.hstack(columns)  # (n, 1 + m or 1 + 2m)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        writer.writerows([f"{x:.17g}" for x in row] for row in table)


def read_command_table(
    path: str | PathLike[str],
) -> tuple[FloatArray, FloatArray, FloatArray | None, list[str]]:
    """Read a table written by ``write_command_table``.

    Returns
    -------
    t : ndarray, shape (n,)
        Time [s].
    lengths : ndarray, shape (n, m)
        Actuator reference lengths [m].
    rates : ndarray, shape (n, m) or None
        Rates [m/s] if the table has ``<name>_rate`` columns for every actuator.
    names : list of str
        The m actuator names.
    """
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    if not rows or not rows[0] or rows[0][0] != "t":
        raise ValueError(f"{path}: expected a header starting with 't', got {rows[:1]!r}")
    header = rows[0][1:]
    data = np.array([[float(x) for x in row] for row in rows[1:] if row], dtype=np.float64)
    data = data.reshape(-1, len(header) + 1)
    # Rates are present iff the second half of the header repeats the names with "_rate".
    half = len(header) // 2
    has_rates = len(header) % 2 == 0 and half > 0 and header[half:] == [
        f"{n}_rate" for n in header[:half]
    ]
    m = half if has_rates else len(header)
    names = header[:m]
    rates = data[:, 1 + m :] if has_rates else None
    return data[:, 0], data[:, 1 : 1 + m], rates, names
