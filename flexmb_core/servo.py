"""Actuator servos: the rest length follows a rate- and acceleration-limited second-order tracker.

A real hydraulic or electric linear actuator does not jump to a commanded length: its position
loop behaves like

    x'' = ωn² (u − x) − 2 ζ ωn x',     |x'| ≤ max_rate,  |x''| ≤ max_accel,

with ``u`` the commanded length (m), ``x`` the actuator's length (m), ``ωn = 2π·bandwidth_hz``
and ``ζ`` the damping ratio. A scene declares it per actuator
(``members.<name>.actuator.servo: {bandwidth_hz, damping_ratio, max_rate, max_accel}``); the
simulator advances it once per time step, between the commanded lengths and the actuator
stretch λ = x / L0, so offline runs, replays and the live node all see the same servo.

Discretization (why this one): over a step the command is held at its value at the step's end,
``u(t_n+1)`` (zero-order hold; a lead of Δt/2, negligible against a servo time constant of
1/ωn ≥ a few ms), and the linear part is advanced by its exact state-transition matrix
Φ(Δt) = exp(A Δt). That is exact for the unsaturated servo and stable for every Δt and every
ζ ≥ 0 (|eig Φ| = e^{−ζ ωn Δt} ≤ 1), where explicit or semi-implicit Euler need ωn Δt < 2 and
would distort the step response at coarse Δt. When the exact step would exceed a limit, the
step is taken at the limited, piecewise-constant acceleration instead
(``a = clip((v_exact − v)/Δt, ±max_accel)``, ``v⁺ = clip(v + a Δt, ±max_rate)``,
``x⁺ = x + (v + v⁺) Δt / 2``): the limits are never exceeded and x stays continuous. The
output is clamped to the actuator's stroke (a hard stop: the rate is zeroed there).

No ROS, no allocation per step (buffers are preallocated per servo set).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ServoParams:
    """Compiled servo parameters of the actuators that declare one.

    ``index (ns,)`` actuator ids (int64, scene order); ``wn (ns,)`` natural frequency ωn = 2π f
    (rad/s); ``zeta (ns,)`` damping ratio (–); ``max_rate (ns,)`` m/s; ``max_accel (ns,)`` m/s²;
    ``stroke (ns, 2)`` admissible lengths (m).
    """

    index: np.ndarray
    wn: np.ndarray
    zeta: np.ndarray
    max_rate: np.ndarray
    max_accel: np.ndarray
    stroke: np.ndarray

    @property
    def size(self) -> int:
        return int(self.index.size)


def transition(wn: np.ndarray, zeta: np.ndarray, dt: float, out: np.ndarray | None = None) -> np.ndarray:
    """Φ = exp(A Δt) of ``A = [[0, 1], [−ωn², −2ζωn]]`` per servo, shape (ns, 2, 2).

    Closed form for a 2 × 2 matrix: Φ = e^{−ζωnΔt} [(C + ζωn S) I + S A] with
    C = cos/1/cosh(sΔt) and S = sin/Δt/sinh(sΔt)/s, s = ωn √|ζ² − 1| (under-, critically, over-damped).
    """
    ns = wn.size
    phi = np.empty((ns, 2, 2)) if out is None else out
    for i in range(ns):
        w, z = float(wn[i]), float(zeta[i])
        d = z * z - 1.0
        if abs(d) < 1e-12:
            c, s_ = 1.0, dt
        elif d < 0.0:
            s = w * math.sqrt(-d)
            c, s_ = math.cos(s * dt), math.sin(s * dt) / s
        else:
            s = w * math.sqrt(d)
            # cosh/sinh of large arguments overflow where the product with the decay does not:
            # e^{−ζωΔt}·cosh(sΔt) = (e^{(s−ζω)Δt} + e^{−(s+ζω)Δt}) / 2
            ep, em = math.exp((s - z * w) * dt), math.exp(-(s + z * w) * dt)
            c, s_ = 0.5 * (ep + em), 0.5 * (ep - em) / s
            phi[i, 0, 0] = c + z * w * s_
            phi[i, 0, 1] = s_
            phi[i, 1, 0] = -w * w * s_
            phi[i, 1, 1] = c + z * w * s_ - 2.0 * z * w * s_
            continue
        e = math.exp(-z * w * dt)
        phi[i, 0, 0] = e * (c + z * w * s_)
        phi[i, 0, 1] = e * s_
        phi[i, 1, 0] = -e * w * w * s_
        phi[i, 1, 1] = e * (c + z * w * s_ - 2.0 * z * w * s_)
    return phi


class Servo:
    """Advances the servos of one model (state lives in :class:`~flexmb_core.model.workspace.State`).

    Parameters
    ----------
    params : the compiled :class:`ServoParams`
    """

    def __init__(self, params: ServoParams):
        self.p = params
        ns = params.size
        self._dt = math.nan
        self._phi = np.zeros((ns, 2, 2))
        self._cols = np.zeros((4, ns))  # Φ00, Φ01, Φ10, Φ11 as contiguous rows
        self._e = np.zeros(ns)          # x − u (m)
        self._v = np.zeros(ns)          # exact rate (m/s)
        self._a = np.zeros(ns)          # m/s²
        self._tmp = np.zeros(ns)
        self._sat = np.zeros(ns, dtype=bool)

    def _transition(self, dt: float) -> np.ndarray:
        if dt != self._dt:              # Δt is constant in a run but for a shortened last step
            transition(self.p.wn, self.p.zeta, dt, self._phi)
            self._cols[:] = self._phi.reshape(-1, 4).T
            self._dt = dt
        return self._cols

    def advance(self, u: np.ndarray, x: np.ndarray, v: np.ndarray, dt: float) -> None:
        """One step of length ``dt`` (s) towards the commanded lengths ``u (ns,)`` (m), in place.

        ``x (ns,)`` output length (m) and ``v (ns,)`` its rate (m/s) are the servo state at the
        step's start on entry and at its end on return.
        """
        p00, p01, p10, p11 = self._transition(dt)
        p = self.p
        e, ve, a, tmp, sat = self._e, self._v, self._a, self._tmp, self._sat
        np.subtract(x, u, out=e)
        # exact unsaturated step of the error dynamics e'' = −ωn² e − 2ζωn e'
        np.multiply(p10, e, out=ve)
        ve += np.multiply(p11, v, out=tmp)
        e *= p00
        e += np.multiply(p01, v, out=tmp)
        # the step's mean acceleration, against both limits
        np.subtract(ve, v, out=a)
        a /= dt
        np.greater(np.abs(a, out=tmp), p.max_accel, out=sat)
        sat |= np.abs(ve, out=tmp) > p.max_rate
        if not sat.any():
            np.add(u, e, out=x)
            v[:] = ve
        else:                           # rare: allocation is fine here
            np.clip(a, -p.max_accel, p.max_accel, out=a)
            v_new = np.clip(v + a * dt, -p.max_rate, p.max_rate)
            x_lim = x + 0.5 * (v + v_new) * dt
            x[:] = np.where(sat, x_lim, u + e)
            v[:] = np.where(sat, v_new, ve)
        # the stroke is a hard stop
        lo, hi = p.stroke[:, 0], p.stroke[:, 1]
        np.less(x, lo, out=sat)
        sat |= x > hi
        if sat.any():
            np.clip(x, lo, hi, out=x)
            v[sat] = 0.0
