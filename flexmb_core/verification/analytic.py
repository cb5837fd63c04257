"""Closed-form and high-accuracy reference solutions for verifying the beam code.

Each function solves a classical beam problem independently of the finite-element code, to a
known accuracy, so tests and benchmarks can compare FE results against it (SPEC §7):

* :func:`euler_bernoulli_cantilever_frequencies` — roots of ``1 + cos x cosh x = 0`` (§7.1).
* :func:`timoshenko_cantilever_frequencies` — the exact clamped–free Timoshenko eigenproblem
  (shear and rotary inertia), also above the second-spectrum cutoff.
* :func:`extensible_elastica_cantilever` — Reissner's geometrically exact planar beam
  (extensible and shearable) under a dead tip force, solved by collocation (§7.11).
* :func:`svk_rollup_tip` / :func:`linear_rollup_tip` — pure-bending roll-up under an end moment for
  a Saint-Venant–Kirchhoff fibre model and for the linear moment–curvature law (§7.2).

All inputs and outputs are SI. Only numpy and scipy are used, and nothing is printed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_bvp
from scipy.optimize import OptimizeResult, brentq, minimize_scalar

from flexmb_core.errors import ConvergenceError

__all__ = [
    "euler_bernoulli_cantilever_frequencies",
    "timoshenko_cantilever_frequencies",
    "extensible_elastica_cantilever",
    "section_moments_rectangle",
    "section_moments_circle",
    "svk_rollup_tip",
    "linear_rollup_tip",
]

_EPS = np.finfo(float).eps


# --------------------------------------------------------------------------------------------
# Input validation
# --------------------------------------------------------------------------------------------
def _require_positive(**values: float) -> None:
    """Raise ``ValueError`` naming the first argument that is not a finite positive number."""
    for name, value in values.items():
        if not (np.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a finite positive number, got {value!r}")


def _require_mode_count(n_modes: int) -> None:
    if isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)) or n_modes < 1:
        raise ValueError(f"n_modes must be a positive integer, got {n_modes!r}")


# --------------------------------------------------------------------------------------------
# 1. Euler–Bernoulli cantilever
# --------------------------------------------------------------------------------------------
def _clamped_free_eb_roots(n_modes: int) -> np.ndarray:
    """Roots ``β_n L`` of ``1 + cos x cosh x = 0``.

    The equation is divided by ``cosh x`` (``cos x + sech x = 0``) so it stays O(1) for large x.
    Exactly one root lies in each interval ``((n-1)π, nπ)``: ``cos`` changes sign once there and
    the positive ``sech x`` only shifts that crossing.

    Returns
    -------
    (n_modes,) float64 — dimensionless ``β_n L``.
    """
    def f(x: float) -> float:
        return math.cos(x) + 1.0 / math.cosh(x)

    roots = [brentq(f, (n - 1) * math.pi, n * math.pi, xtol=1e-15, rtol=4 * _EPS)
             for n in range(1, n_modes + 1)]
    return np.array(roots)


def euler_bernoulli_cantilever_frequencies(EI: float, rhoA: float, L: float,
                                           n_modes: int) -> np.ndarray:
    """Bending natural frequencies of a clamped–free Euler–Bernoulli beam.

    ``ω_n = (β_n L)² √(EI / (ρA L⁴))`` with ``β_n L`` the roots of ``1 + cos x cosh x = 0``,
    solved numerically (1.875104, 4.694091, 7.854757, …).

    Parameters
    ----------
    EI : float — bending stiffness (N·m²).
    rhoA : float — mass per unit length (kg/m).
    L : float — length (m).
    n_modes : int — number of modes.

    Returns
    -------
    (n_modes,) float64 — circular frequencies ω_n (rad/s), ascending.
    """
    _require_positive(EI=EI, rhoA=rhoA, L=L)
    _require_mode_count(n_modes)
    beta_l = _clamped_free_eb_roots(int(n_modes))
    return beta_l**2 * math.sqrt(EI / (rhoA * L**4))


# --------------------------------------------------------------------------------------------
# 2. Timoshenko cantilever
# --------------------------------------------------------------------------------------------
# Dimensionless form (ξ = x/L, w̃ = w/L, Ω = ω/ω0, ω0 = √(EI/(ρA L⁴))):
#   w̃'' − ψ' + r w̃ = 0,   ψ'' + g (w̃' − ψ) + m ψ = 0,
#   r = Ω²/g,  m = q Ω²,  g = kGA L²/EI,  q = I/(A L²).
# A solution ∝ exp(sξ) requires S = s² to solve  S² + (r + m) S + r (m − g) = 0.
# Both roots are real for Ω > 0. Below the cutoff (m < g) one root is positive; above it both
# are negative. The second spectrum starts at m = g, i.e. ω_c = √(kGA/(ρI)).


@dataclass(frozen=True)
class _TimoshenkoParameters:
    """Dimensionless parameters of a uniform Timoshenko beam.

    g : kGA L²/EI — shear stiffness relative to bending (→ ∞ is Euler–Bernoulli).
    q : I/(A L²) — squared slenderness ratio (rotary inertia relative to translational).
    """

    g: float
    q: float


def _characteristic_roots(omega: float, p: _TimoshenkoParameters) -> tuple[float, float]:
    """Roots ``S1 ≥ S2`` of ``S² + (r+m) S + r(m−g) = 0`` at dimensionless frequency ``omega``.

    The discriminant is written as ``(r−m)² + 4rg`` so it is visibly positive. ``S1`` comes from
    the product of the roots, which has no cancellation, so ``S1`` passes smoothly through zero
    at the cutoff.
    """
    r = omega**2 / p.g
    m = p.q * omega**2
    s2 = -0.5 * ((r + m) + math.sqrt((r - m) ** 2 + 4.0 * r * p.g))
    s1 = r * (m - p.g) / s2
    return s1, s2


def _scaled_cosine_sine(S: float) -> tuple[float, float, float]:
    """``C(S) = cosh √S`` and ``Sn(S) = sinh(√S)/√S`` (cos/sin for S < 0), scaled to stay finite.

    Both are entire functions of S, so the basis they build does not degenerate at S = 0 (the
    cutoff frequency). For S > 0 they are multiplied by ``w = 1/cosh √S`` so that large
    ``√S`` cannot overflow. A positive factor on a matrix column does not change the sign of
    the determinant.

    Returns
    -------
    (w·C, w·Sn, w) : tuple of float.
    """
    if abs(S) < 1e-8:
        # Series to O(S²); the next term is ~S³/720, far below rounding.
        return 1.0 + S / 2.0 + S * S / 24.0, 1.0 + S / 6.0 + S * S / 120.0, 1.0
    if S < 0.0:
        b = math.sqrt(-S)
        return math.cos(b), math.sin(b) / b, 1.0
    a = math.sqrt(S)
    e = math.exp(-2.0 * a)
    w = 2.0 * math.exp(-a) / (1.0 + e)       # 1/cosh a without overflow
    return 1.0, (1.0 - e) / (1.0 + e) / a, w  # tanh(a)/a


def _timoshenko_determinant(omega: float, p: _TimoshenkoParameters) -> float:
    """Determinant of the clamped–free boundary matrix at dimensionless frequency ``omega``.

    For each root S of the characteristic equation two solutions are used:
    ``φ1 = (w̃, ψ) = (C, (S+r) Sn)`` and ``φ2 = (S·Sn, (S+r) C)``, with ``C' = S·Sn`` and
    ``Sn' = C``. At S = 0 they become ``(1, rξ)`` and ``(0, r)``, which are still independent.
    Rows: ``w̃(0) = 0``, ``ψ(0) = 0``, ``ψ'(1) = 0`` (moment), and ``(w̃' − ψ)(1) = 0`` (shear,
    divided by the constant −r). The determinant is a continuous real function of ω and is
    zero exactly at the eigenfrequencies.
    """
    r = omega**2 / p.g
    columns = []
    for S in _characteristic_roots(omega, p):
        c, sn, w = _scaled_cosine_sine(S)
        columns.append([w, 0.0, (S + r) * c, sn])              # φ1
        columns.append([0.0, (S + r) * w, (S + r) * S * sn, c])  # φ2
    return float(np.linalg.det(np.array(columns).T))           # (4, 4)


def _phase(omega: float, p: _TimoshenkoParameters) -> float:
    """Sum of the oscillatory wavenumbers ``√(−S)`` over both roots (dimensionless).

    It increases monotonically with ω, and there is roughly one eigenfrequency per π of phase.
    The frequency scan is therefore uniform in phase, not in ω.
    """
    if omega == 0.0:
        return 0.0          # both roots are zero there; the quotient for S1 would be 0/0
    s1, s2 = _characteristic_roots(omega, p)
    return math.sqrt(max(-s1, 0.0)) + math.sqrt(-s2)


def _omega_at_phase(target: float, omega_lo: float, p: _TimoshenkoParameters) -> float:
    """Dimensionless frequency at which :func:`_phase` equals ``target`` (≥ ``omega_lo``)."""
    omega_hi = max(2.0 * omega_lo, 1.0)
    while _phase(omega_hi, p) < target:
        omega_lo, omega_hi = omega_hi, 2.0 * omega_hi
    return brentq(lambda om: _phase(om, p) - target, omega_lo, omega_hi,
                  xtol=1e-14 * omega_hi, rtol=4 * _EPS)


def _split_touching_pair(a: float, b: float, sign: float,
                         p: _TimoshenkoParameters) -> list[tuple[float, float]]:
    """Find two close roots in ``[a, b]`` that the scan missed because the sign did not change.

    ``sign`` is the sign of the determinant at ``a`` and ``b``. If the determinant has a local
    minimum of ``sign·det`` that falls below zero, the two brackets on either side of it are
    returned. Otherwise an empty list is returned.
    """
    res = minimize_scalar(lambda om: sign * _timoshenko_determinant(om, p), bounds=(a, b),
                          method="bounded", options={"xatol": 1e-13 * b})
    if res.fun < 0.0:
        return [(a, res.x), (res.x, b)]
    return []


def _brackets_at(i: int, det: list[float], omega: list[float],
                 p: _TimoshenkoParameters) -> list[tuple[float, float]]:
    """Root brackets contributed by scan sample ``i`` (needs samples ``i-1`` to ``i+1``)."""
    if det[i] == 0.0:
        return [(omega[i], omega[i])]
    if det[i] * det[i + 1] < 0.0:
        return [(omega[i], omega[i + 1])]
    if abs(det[i]) < abs(det[i - 1]) and abs(det[i]) < abs(det[i + 1]) \
            and det[i] * det[i - 1] > 0.0:
        # Two roots closer than one scan step leave no sign change. A local minimum of |det|
        # could hide such a pair, so check it.
        return _split_touching_pair(omega[i - 1], omega[i + 1], math.copysign(1.0, det[i]), p)
    return []


def _refine(bracket: tuple[float, float], p: _TimoshenkoParameters) -> float:
    a, b = bracket
    if a == b:
        return a
    return brentq(lambda om: _timoshenko_determinant(om, p), a, b, xtol=1e-15 * b, rtol=4 * _EPS)


def _timoshenko_roots(p: _TimoshenkoParameters, n_modes: int,
                      steps_per_pi: int = 32) -> np.ndarray:
    """First ``n_modes`` dimensionless eigenfrequencies Ω (ascending).

    The determinant is sampled at ``steps_per_pi`` points per π of phase, one π block at a time,
    until enough roots are bracketed. Each bracket is then refined with brentq. Sample 0 is
    ω = 0, where the determinant means nothing (r = 0 makes the basis degenerate). It serves only
    as the left neighbour of sample 1, and no bracket starts there.
    """
    omega = [0.0]
    det = [math.nan]        # NaN fails every comparison, so sample 1 is never taken as a minimum
    brackets: list[tuple[float, float]] = []
    max_blocks = 4 * (n_modes + 4)
    for block in range(max_blocks):
        for j in range(1, steps_per_pi + 1):
            omega.append(_omega_at_phase(math.pi * (block + j / steps_per_pi), omega[-1], p))
            det.append(_timoshenko_determinant(omega[-1], p))
            if len(omega) >= 3:
                brackets.extend(_brackets_at(len(omega) - 2, det, omega, p))
        if len(brackets) >= n_modes:
            roots = sorted(_refine(br, p) for br in brackets)
            return np.array(roots[:n_modes])
    raise ConvergenceError(
        f"Timoshenko frequency scan found only {len(brackets)} of {n_modes} roots in "
        f"{max_blocks} phase blocks (g = {p.g:.6g}, q = {p.q:.6g})")


def timoshenko_cantilever_frequencies(E: float, G: float, k_shear: float, A: float, I: float,
                                      rho: float, L: float, n_modes: int) -> np.ndarray:
    """Bending natural frequencies of a uniform clamped–free Timoshenko beam.

    Solves the two-field eigenproblem (deflection w, section rotation ψ)::

        k G A (w'' − ψ') + ρ A ω² w = 0
        E I ψ'' + k G A (w' − ψ) + ρ I ω² ψ = 0
        w(0) = ψ(0) = 0,   ψ'(L) = 0,   w'(L) − ψ(L) = 0

    The exact solution gives a 4×4 boundary matrix. Its basis uses entire functions of the
    characteristic root, so it stays valid through the second-spectrum cutoff
    ``ω_c = √(kGA/(ρI))`` and above it. The determinant is scanned uniformly in wavenumber
    phase and the roots are refined with brentq. They are reproducible to about 1e-12 relative,
    which is the limit set by the conditioning of the determinant. Close pairs that give no sign
    change are caught by a local-minimum check.

    Parameters
    ----------
    E, G : float — Young's and shear modulus (Pa).
    k_shear : float — shear correction factor (-), e.g. 5/6 for a rectangle.
    A : float — area (m²).
    I : float — second moment of area about the bending axis (m⁴).
    rho : float — density (kg/m³).
    L : float — length (m).
    n_modes : int — number of modes, counted over both spectra.

    Returns
    -------
    (n_modes,) float64 — circular frequencies ω_n (rad/s), ascending.

    Raises
    ------
    ConvergenceError
        If the scan does not find ``n_modes`` roots.
    """
    _require_positive(E=E, G=G, k_shear=k_shear, A=A, I=I, rho=rho, L=L)
    _require_mode_count(n_modes)
    p = _TimoshenkoParameters(g=k_shear * G * A * L**2 / (E * I), q=I / (A * L**2))
    omega0 = math.sqrt(E * I / (rho * A * L**4))
    return omega0 * _timoshenko_roots(p, int(n_modes))


# --------------------------------------------------------------------------------------------
# 3. Extensible, shearable elastica (Reissner beam) under a dead tip force
# --------------------------------------------------------------------------------------------
# Dimensionless: s = S/L, X = x/L, Z = z/L, m = M L/EI, k = P L²/EI, e = P/EA, c = P/GA_s.
# φ is the section rotation about +y, so φ > 0 turns the axis from +x toward −z. Directors:
# d1 = (cos φ, −sin φ), d2 = (sin φ, cos φ) in (x, z). The internal force equals the tip
# force n = (0, −P), so N = n·d1 = P sin φ and Q = n·d2 = −P cos φ. The moment about y of the
# load beyond S is M = P (x_L − x).
#   X' = (1+ε) cos φ + γ sin φ,   Z' = −(1+ε) sin φ + γ cos φ,   φ' = m,   m' = −k X'
#   ε = e sin φ,   γ = −c cos φ,   U' = ½ (m² + k e sin²φ + k c cos²φ)   (U in units EI/L)
# BCs: X(0) = Z(0) = φ(0) = 0, m(1) = 0, U(0) = 0.


def _elastica_rhs(k: float, e: float, c: float) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Right-hand side ``y' = f(s, y)`` for ``y = (X, Z, φ, m, U)`` of shape (5, n)."""
    def rhs(s: np.ndarray, y: np.ndarray) -> np.ndarray:
        phi, m = y[2], y[3]
        sin, cos = np.sin(phi), np.cos(phi)
        stretch = 1.0 + e * sin         # 1 + ε
        shear = -c * cos                # γ
        dx = stretch * cos + shear * sin
        dz = -stretch * sin + shear * cos
        du = 0.5 * (m * m + k * e * sin**2 + k * c * cos**2)
        return np.vstack([dx, dz, m, -k * dx, du])  # (5, n)
    return rhs


def _elastica_bc(ya: np.ndarray, yb: np.ndarray) -> np.ndarray:
    return np.array([ya[0], ya[1], ya[2], yb[3], ya[4]])


def _linear_elastica_guess(s: np.ndarray, k: float, c: float) -> np.ndarray:
    """Small-load (linear Timoshenko) solution on the mesh ``s`` (n,), as the first guess (5, n)."""
    phi = k * (s - 0.5 * s**2)
    z = -k * (0.5 * s**2 - s**3 / 6.0) - c * s
    u = 0.5 * k**2 * (s - s**2 + s**3 / 3.0)
    return np.vstack([s, z, phi, k * (1.0 - s), u])


def extensible_elastica_cantilever(L: float, EI: float, EA: float, GA_s: float, P: float, *,
                                   n_nodes: int = 201, tol: float = 1e-10,
                                   max_load_step: float = 1.0) -> dict:
    """Planar Reissner cantilever (extensible, shearable) under a dead transverse tip force.

    The cantilever is clamped at the origin along +x. A tip force of magnitude ``P`` acts in −z
    and keeps its direction (dead load). Linear constitutive laws ``ε = N/EA``, ``γ = Q/GA_s``,
    ``κ = M/EI`` are used, where N and Q are the components of the tip force in the current
    section frame. The boundary-value problem is solved with ``scipy.integrate.solve_bvp``,
    with continuation in load of at most ``max_load_step`` in ``k = P L²/EI`` per step and the
    last step at ``tol``. As EA, GA_s → ∞ the solution tends to the inextensible elastica
    (SPEC §7.11). For small P it tends to ``δ = P L³/(3EI) + P L/GA_s``.

    Parameters
    ----------
    L : float — length (m).
    EI, EA, GA_s : float — bending (N·m²), axial (N) and shear (N) stiffness.
    P : float — tip force magnitude (N), positive in −z.
    n_nodes : int — number of evenly spaced points in the returned shape arrays.
    tol : float — ``solve_bvp`` tolerance of the final step (relative collocation residual).
    max_load_step : float — largest increment of ``P L²/EI`` per continuation step.

    Returns
    -------
    dict with
        ``x_tip``, ``z_tip`` : float — tip position (m).
        ``rotation_tip`` : float — tip section rotation about +y (rad). Positive when the tip
        turns toward −z.
        ``strain_energy`` : float — ``∫ ½(EI κ² + EA ε² + GA_s γ²) dS`` (J).
        ``potential_energy`` : float — strain energy + ``P z_tip`` (J).
        ``arc_length`` : (n_nodes,) — reference arc length S (m).
        ``x``, ``z`` : (n_nodes,) — deformed axis positions (m).
        ``rotation`` : (n_nodes,) — section rotation (rad).
        ``moment`` : (n_nodes,) — bending moment M (N·m).
        ``shape`` : callable ``S -> (3, n)`` giving (x, z, rotation) at arc lengths S (m), from
        the collocation interpolant.
        ``n_mesh`` : int — collocation mesh size of the final solve.

    Raises
    ------
    ConvergenceError
        If a ``solve_bvp`` step does not converge.
    """
    _require_positive(L=L, EI=EI, EA=EA, GA_s=GA_s, tol=tol, max_load_step=max_load_step)
    if not np.isfinite(P):
        raise ValueError(f"P must be finite, got {P!r}")
    if n_nodes < 2:
        raise ValueError(f"n_nodes must be at least 2, got {n_nodes!r}")
    k_final = P * L**2 / EI
    n_steps = max(1, math.ceil(abs(k_final) / max_load_step))
    s = np.linspace(0.0, 1.0, 41)
    y = _linear_elastica_guess(s, k_final / n_steps, P / GA_s / n_steps)
    for step in range(1, n_steps + 1):
        frac = step / n_steps
        k, e, c = frac * k_final, frac * P / EA, frac * P / GA_s
        last = step == n_steps
        # Intermediate steps only need to give a good guess, so use a looser tolerance there.
        sol = solve_bvp(_elastica_rhs(k, e, c), _elastica_bc, s, y,
                        tol=tol if last else max(tol, 1e-6),
                        bc_tol=tol * 1e-2 if last else None, max_nodes=200_000)
        if not sol.success:
            raise ConvergenceError(
                f"extensible elastica: solve_bvp failed at k = PL²/EI = {k:.6g} "
                f"(step {step}/{n_steps}): {sol.message}; try a smaller max_load_step")
        s, y = sol.x, sol.y
    return _elastica_output(sol, L, EI, P, n_nodes)


def _elastica_output(sol: OptimizeResult, L: float, EI: float, P: float, n_nodes: int) -> dict:
    """Convert the dimensionless collocation solution into the documented dict."""
    moment_scale = EI / L

    def shape(S: np.ndarray | float) -> np.ndarray:
        yy = sol.sol(np.asarray(S, dtype=float) / L)
        return np.array([yy[0] * L, yy[1] * L, yy[2]])

    S = np.linspace(0.0, L, n_nodes)
    yy = sol.sol(S / L)       # (5, n_nodes)
    tip = sol.y[:, -1]
    strain_energy = float(tip[4] * moment_scale)
    return {
        "x_tip": float(tip[0] * L),
        "z_tip": float(tip[1] * L),
        "rotation_tip": float(tip[2]),
        "strain_energy": strain_energy,
        "potential_energy": strain_energy + P * float(tip[1] * L),
        "arc_length": S,
        "x": yy[0] * L,
        "z": yy[1] * L,
        "rotation": yy[2].copy(),
        "moment": yy[3] * moment_scale,
        "shape": shape,
        "n_mesh": int(sol.x.size),
    }


# --------------------------------------------------------------------------------------------
# 4. Roll-up under an end moment: SVK fibre model and linear law
# --------------------------------------------------------------------------------------------
def section_moments_rectangle(b: float, h: float) -> np.ndarray:
    """Area moments ``∫ s^k dA``, k = 0..4, of a b × h rectangle about its centroid.

    Parameters
    ----------
    b : float — width normal to the bending plane (m).
    h : float — height in the bending plane, the direction of s (m).

    Returns
    -------
    (5,) float64 — ``[b h, 0, b h³/12, 0, b h⁵/80]`` (m^(2+k)).
    """
    _require_positive(b=b, h=h)
    return np.array([b * h, 0.0, b * h**3 / 12.0, 0.0, b * h**5 / 80.0])


def section_moments_circle(r: float) -> np.ndarray:
    """Area moments ``∫ s^k dA``, k = 0..4, of a solid disc of radius r about its centre.

    Returns
    -------
    (5,) float64 — ``[π r², 0, π r⁴/4, 0, π r⁶/8]`` (m^(2+k)).
    """
    _require_positive(r=r)
    return np.array([math.pi * r**2, 0.0, math.pi * r**4 / 4.0, 0.0, math.pi * r**6 / 8.0])


def _svk_strain_coefficients(a: float, theta: float) -> np.ndarray:
    """Coefficients ``p`` (3,) of ``E11(ŝ) = p0 + p1 ŝ + p2 ŝ²`` with ŝ = s/L and λ = a − ŝθ."""
    # (a−1)(a+1) rather than a²−1, because a ≈ 1 and the difference is what matters.
    return np.array([0.5 * (a - 1.0) * (a + 1.0), -a * theta, 0.5 * theta**2])


def _svk_gradient_hessian(x: np.ndarray, gram: np.ndarray,
                          mu: float) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (2,) and Hessian (2, 2) of ``Π̂(a, θ) = ½ pᵀ G p − μ θ``.

    ``Π̂ = Π/(E A L)`` with ``G_ij = ∫ ŝ^(i+j) dA / A`` (3, 3) and ``μ = M/(E A L)``.
    """
    a, theta = x
    p = _svk_strain_coefficients(a, theta)
    jac = np.array([[a, 0.0], [-theta, -a], [0.0, theta]])       # ∂p/∂(a, θ)  (3, 2)
    gp = gram @ p                                                 # (3,)
    grad = jac.T @ gp - np.array([0.0, mu])
    # Second derivatives: ∂²p0/∂a² = 1, ∂²p1/∂a∂θ = −1, ∂²p2/∂θ² = 1.
    curvature_terms = np.array([[gp[0], -gp[1]], [-gp[1], gp[2]]])
    return grad, jac.T @ gram @ jac + curvature_terms


def svk_rollup_tip(L: float, M: float, E: float, section_moments: np.ndarray, *,
                   tol: float = 1e-14, max_iter: int = 50) -> dict:
    """Roll-up of a straight cantilever by a conservative end moment, SVK fibres, ν = 0.

    Model: the axis stays a circular arc. A fibre at distance s from the centroid (in the
    bending plane, positive toward the centre of curvature) has stretch
    ``λ(s) = λ0 − s θ/L`` and Green strain ``E11 = ½(λ² − 1)``, with no transverse coupling.
    The potential is ``Π(λ0, θ) = L ∫ ½ E E11² dA − M θ``. It is a polynomial whose section
    integrals are the area moments ``∫ s^k dA`` (k = 0..4). The stationarity equations are
    solved by damped Newton, and the Hessian is checked to be positive definite (a stable
    minimum).

    For thin sections the result tends to :func:`linear_rollup_tip`. A rectangle's bending
    stiffness softens as ``M ≈ EI κ (1 − 0.3 (κ h)²)`` (SPEC §7.2).

    Parameters
    ----------
    L : float — length (m).
    M : float — end moment (N·m). Positive rolls the beam toward +y.
    E : float — Young's modulus (Pa).
    section_moments : (5,) array — ``∫ s^k dA`` for k = 0..4 (m^(2+k)), e.g. from
        :func:`section_moments_rectangle`.
    tol : float — convergence tolerance on the Newton step: ``|Δλ0| ≤ tol`` and
        ``|Δθ| ≤ tol·max(1, |θ|)``.
    max_iter : int — Newton iteration limit.

    Returns
    -------
    dict with
        ``stretch`` : float — axis stretch λ0 (-).
        ``rotation`` : float — end rotation θ (rad).
        ``curvature`` : float — θ/L, per reference length (1/m).
        ``x``, ``y`` : float — tip position (m), with ``R = λ0 L/θ``, ``x = R sin θ``,
        ``y = R (1 − cos θ)``.
        ``iterations`` : int — Newton iterations used.

    Raises
    ------
    ConvergenceError
        If Newton does not converge, or converges to a point that is not a minimum.
    """
    _require_positive(L=L, E=E, tol=tol)
    moments = np.asarray(section_moments, dtype=float)
    if moments.shape != (5,) or not moments[0] > 0.0 or not moments[2] > 0.0:
        raise ValueError("section_moments must be ∫ s^k dA for k = 0..4 (shape (5,)) with "
                         f"positive area and second moment, got {section_moments!r}")
    if not np.isfinite(M):
        raise ValueError(f"M must be finite, got {M!r}")
    # ∫ ŝ^(i+j) dA / A with ŝ = s/L; dividing by A and L^k makes every entry O(1) or smaller.
    normalized = moments / (moments[0] * L ** np.arange(5))      # (5,)
    gram = normalized[np.add.outer(np.arange(3), np.arange(3))]  # (3, 3)
    mu = M / (E * moments[0] * L)
    x = np.array([1.0, M * L / (E * moments[2])])                # start from the linear solution
    for iteration in range(1, max_iter + 1):
        grad, hess = _svk_gradient_hessian(x, gram, mu)
        step = -np.linalg.solve(hess, grad)
        # Limit the step so a poor start (thick section, large M) cannot jump across a fold.
        scale = min(1.0, 0.1 / max(abs(step[0]), 1e-300), 0.5 / max(abs(step[1]), 1e-300))
        x = x + scale * step
        if scale == 1.0 and abs(step[0]) <= tol and abs(step[1]) <= tol * max(1.0, abs(x[1])):
            break
    else:
        raise ConvergenceError(f"SVK roll-up: Newton did not converge in {max_iter} iterations "
                               f"(M = {M:.6g} N·m, last step {step}); M may exceed the limit "
                               "moment of an SVK section, whose compressed fibres soften")
    _, hess = _svk_gradient_hessian(x, gram, mu)
    if np.any(np.linalg.eigvalsh(hess) <= 0.0):
        raise ConvergenceError(f"SVK roll-up: equilibrium at λ0 = {x[0]:.6g}, θ = {x[1]:.6g} is "
                               "not a minimum (the compressed fibres have passed the SVK limit "
                               "point); reduce M or the section depth")
    stretch, theta = float(x[0]), float(x[1])
    return {"stretch": stretch, "rotation": theta, "curvature": theta / L,
            **_arc_tip(stretch * L, theta), "iterations": iteration}


def _arc_tip(length: float, theta: float) -> dict:
    """Tip of a circular arc of the given current length turned through ``theta`` (rad).

    ``x = ℓ sin θ/θ`` and ``y = ℓ (1 − cos θ)/θ = ℓ sin(θ/2) · sinc(θ/2)``. Both are written
    with ``np.sinc``, so θ = 0 needs no special case.
    """
    half_sinc = float(np.sinc(theta / (2.0 * math.pi)))      # sin(θ/2)/(θ/2)
    return {"x": length * float(np.sinc(theta / math.pi)),
            "y": length * math.sin(0.5 * theta) * half_sinc}


def linear_rollup_tip(L: float, M: float, EI: float) -> dict:
    """Exact roll-up for a linear moment–curvature law: an inextensible circular arc.

    Parameters
    ----------
    L : float — length (m).
    M : float — end moment (N·m). Positive rolls the beam toward +y.
    EI : float — bending stiffness (N·m²).

    Returns
    -------
    dict with ``rotation`` θ = ML/EI (rad), ``curvature`` M/EI (1/m), and tip ``x = L sin θ/θ``,
    ``y = L (1 − cos θ)/θ`` (m).
    """
    _require_positive(L=L, EI=EI)
    theta = M * L / EI
    return {"rotation": theta, "curvature": M / EI, **_arc_tip(L, theta)}


def svk_rollup_tip_relaxed_section(L: float, M: float, E: float, width: float, height: float, *,
                                   E_t: float | None = None, n_gauss: int = 8) -> dict:
    """Roll-up of a rectangular SVK cantilever whose in-plane section fibre may shrink.

    Same fibre model as :func:`svk_rollup_tip`, plus the freedom the positional frame has: the
    in-plane section vector keeps its direction but takes a length μ (transverse Green strain
    ``E22 = ½(μ² − 1)``, stiffness ``E_t``, no Poisson coupling). Fibre stretch becomes
    ``λ(s) = λ0 − μ s θ/L``. Stationarity of
    ``Π = L[∫ ½E E11² dA + ½ E_t E22² A] − M θ`` in (λ0, θ, μ) is solved to machine precision.
    Bending softens by about twice the rigid-section value: at a full circle with h/L = 1/100
    the tip misses the root by 1.85e-3·L instead of 1.19e-3·L.

    Parameters
    ----------
    L : float — length (m).  M : float — end moment (N·m).  E : float — Young's modulus (Pa).
    width, height : float — section sizes (m); ``height`` lies in the bending plane.
    E_t : float — transverse modulus (Pa), default E (the frame law of SPEC §1.2).

    Returns
    -------
    dict with ``stretch`` λ0, ``rotation`` θ, ``section_stretch`` μ and tip ``x``, ``y`` (m).
    """
    from scipy.optimize import fsolve

    _require_positive(L=L, E=E, width=width, height=height)
    e_t = E if E_t is None else E_t
    xg, wg = np.polynomial.legendre.leggauss(n_gauss)
    s = 0.5 * height * xg
    ws = 0.5 * height * wg * width
    area = width * height

    def gradient(p: np.ndarray) -> np.ndarray:
        a, th, mu = p
        lam = a - mu * th / L * s
        e11 = 0.5 * (lam * lam - 1.0)
        f = E * e11 * lam * ws
        return np.array([L * f.sum(), -(f * mu * s).sum() - M,
                         L * (-(f * th / L * s).sum() + e_t * 0.5 * (mu * mu - 1.0) * mu * area)])

    lin = linear_rollup_tip(L, M, E * width * height**3 / 12.0)
    sol, info, ier, msg = fsolve(gradient, np.array([1.0, lin["rotation"], 1.0]), xtol=1e-15, full_output=True)
    if ier != 1 and np.abs(gradient(sol)).max() > 1e-9 * max(abs(M), 1e-300):
        raise ConvergenceError(f"relaxed-section roll-up did not converge: {msg}")
    a, th, mu = sol
    return {"stretch": float(a), "rotation": float(th), "section_stretch": float(mu),
            **_arc_tip(a * L, th)}
