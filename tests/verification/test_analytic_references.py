"""Checks of the reference solutions in ``flexmb_core.verification.analytic``.

Each reference is checked against something computed another way: tabulated roots, a fine
finite-element model written here, an elliptic-integral quadrature of the elastica, an energy
derivative, section quadrature, or an asymptotic expansion. The reference must be correct before
the solver is judged against it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.integrate import quad
from scipy.optimize import brentq
from scipy.special import roots_chebyu

from flexmb_core.verification import analytic
from flexmb_core.verification.analytic import (
    euler_bernoulli_cantilever_frequencies,
    extensible_elastica_cantilever,
    linear_rollup_tip,
    section_moments_circle,
    section_moments_rectangle,
    svk_rollup_tip,
    timoshenko_cantilever_frequencies,
)

# Steel with ν = 0.3 and Cowper-like k = 5/6. These give a realistic shear-to-bending ratio.
E_STEEL, G_STEEL, K_RECT, RHO_STEEL = 210e9, 210e9 / 2.6, 5.0 / 6.0, 7850.0


def _square_beam(slenderness: float, L: float = 1.0) -> dict:
    """Parameters of a square steel cantilever with L/h = ``slenderness``."""
    h = L / slenderness
    return dict(E=E_STEEL, G=G_STEEL, k_shear=K_RECT, A=h * h, I=h**4 / 12.0, rho=RHO_STEEL, L=L)


# --------------------------------------------------------------------------------------------
# An independent Timoshenko FE model (used only here)
# --------------------------------------------------------------------------------------------
def _timoshenko_element(length: float, EI: float, kGA: float, rhoA: float,
                        rhoI: float) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and consistent mass (4, 4) of a 2-node Timoshenko element, DOFs (w1, ψ1, w2, ψ2).

    Interdependent interpolation: the shape functions are the exact static solution,
    w = c0 + c1 x + c2 x² + c3 x³ and ψ = w' − γ with constant shear strain γ = −6 c3 EI/kGA.
    So the stiffness is exact and cannot lock. The consistent mass from the same functions makes
    the frequencies converge as O(h²).
    """
    phi = 6.0 * EI / kGA

    def w_row(x):   # (4,) coefficients of w in c
        return np.array([1.0, x, x * x, x**3])

    def psi_row(x):
        return np.array([0.0, 1.0, 2.0 * x, 3.0 * x * x + phi])

    nodal = np.array([w_row(0.0), psi_row(0.0), w_row(length), psi_row(length)])  # c → DOFs
    coeff = np.linalg.inv(nodal)                                                 # (4, 4)
    xg, wg = np.polynomial.legendre.leggauss(5)     # exact for the degree-6 mass integrand
    xg, wg = 0.5 * length * (xg + 1.0), 0.5 * length * wg
    K = np.zeros((4, 4))
    M = np.zeros((4, 4))
    for x, wq in zip(xg, wg):
        n_w, n_psi = w_row(x) @ coeff, psi_row(x) @ coeff
        b_bend = np.array([0.0, 0.0, 2.0, 6.0 * x]) @ coeff                        # ψ'
        b_shear = np.array([0.0, 1.0, 2.0 * x, 3.0 * x * x]) @ coeff - n_psi      # w' − ψ
        K += wq * (EI * np.outer(b_bend, b_bend) + kGA * np.outer(b_shear, b_shear))
        M += wq * (rhoA * np.outer(n_w, n_w) + rhoI * np.outer(n_psi, n_psi))
    return K, M


def _timoshenko_fe_frequencies(beam: dict, n_elements: int, n_modes: int) -> np.ndarray:
    """Lowest ``n_modes`` circular frequencies (rad/s) of the clamped–free FE model.

    Shift-invert Lanczos on the sparse matrices is used. Dense generalized ``eigh`` loses about
    1e-6 on slender beams, where the shear stiffness makes K ill-conditioned.
    """
    E, I, A, rho = beam["E"], beam["I"], beam["A"], beam["rho"]
    Ke, Me = _timoshenko_element(beam["L"] / n_elements, E * I, beam["k_shear"] * beam["G"] * A,
                                 rho * A, rho * I)
    dofs = 2 * np.arange(n_elements)[:, None] + np.arange(4)[None, :]           # (ne, 4)
    rows = np.repeat(dofs, 4, axis=1).ravel()
    cols = np.tile(dofs, (1, 4)).ravel()
    n = 2 * (n_elements + 1)
    K = sp.coo_matrix((np.tile(Ke.ravel(), n_elements), (rows, cols)), shape=(n, n)).tocsc()
    M = sp.coo_matrix((np.tile(Me.ravel(), n_elements), (rows, cols)), shape=(n, n)).tocsc()
    free = np.arange(2, n)                                                      # clamp w, ψ at 0
    K, M = K[free][:, free], M[free][:, free]
    lam = spla.eigsh(K, k=n_modes, M=M, sigma=0.0, which="LM", tol=0.0,
                     return_eigenvectors=False)
    return np.sqrt(np.sort(lam))


def _richardson_fe_frequencies(beam: dict, n_elements: int, n_modes: int) -> tuple[np.ndarray,
                                                                                     np.ndarray]:
    """(raw, extrapolated) frequencies: FE with 2n elements, and with the O(h²) term removed."""
    coarse = _timoshenko_fe_frequencies(beam, n_elements, n_modes)
    fine = _timoshenko_fe_frequencies(beam, 2 * n_elements, n_modes)
    return fine, (4.0 * fine - coarse) / 3.0


# --------------------------------------------------------------------------------------------
# 1. Euler–Bernoulli
# --------------------------------------------------------------------------------------------
def test_eb_roots_match_tabulated_values_and_characteristic_equation():
    beta_l = np.sqrt(euler_bernoulli_cantilever_frequencies(EI=1.0, rhoA=1.0, L=1.0, n_modes=12))
    tabulated = np.array([1.875104, 4.694091, 7.854757, 10.995541, 14.137168])
    assert np.max(np.abs(beta_l[:5] - tabulated)) <= 5e-7          # table is rounded to 1e-6
    # Residual of 1 + cos x cosh x divided by cosh x, the size of its terms. The limit is the
    # rounding of x itself (about x·eps, and x reaches 36).
    assert np.max(np.abs(np.cos(beta_l) + 1.0 / np.cosh(beta_l))) <= 1e-14
    # For large n the roots approach (2n − 1)π/2, with an error of about 2 exp(−(2n−1)π/2).
    n = np.arange(8, 13)
    assert np.max(np.abs(beta_l[7:] - (2 * n - 1) * np.pi / 2)) <= 1e-9


def test_eb_frequencies_reproduce_spec_71_hz():
    # SPEC §7.1: L = 1 m, 10 × 20 mm steel, E = 210 GPa, ρ = 7850.
    rhoA = RHO_STEEL * 0.01 * 0.02
    f_thin = euler_bernoulli_cantilever_frequencies(E_STEEL * 0.02 * 0.01**3 / 12, rhoA, 1.0,
                                                    4) / (2 * np.pi)
    f_thick = euler_bernoulli_cantilever_frequencies(E_STEEL * 0.01 * 0.02**3 / 12, rhoA, 1.0,
                                                     2) / (2 * np.pi)
    # Compare to the number of digits SPEC prints.
    assert np.all(np.abs(f_thin - [8.36, 52.36, 146.61, 287.3]) <= [5e-3, 5e-3, 5e-3, 5e-2])
    assert np.all(np.abs(f_thick - [16.71, 104.72]) <= 5e-3)


# --------------------------------------------------------------------------------------------
# 2. Timoshenko
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("slenderness", [10.0, 20.0, 100.0])
def test_timoshenko_matches_fine_fe_model(slenderness):
    beam = _square_beam(slenderness)
    exact = timoshenko_cantilever_frequencies(**beam, n_modes=5)
    raw, extrapolated = _richardson_fe_frequencies(beam, n_elements=800, n_modes=5)
    # 1600 elements: the FE error is O(h²), a few 1e-7 at mode 5.
    assert np.max(np.abs(raw / exact - 1.0)) <= 1e-5
    # With the h² term removed, what is left is the h⁴ term plus the eigen-solver's rounding.
    assert np.max(np.abs(extrapolated / exact - 1.0)) <= 1e-7


def test_timoshenko_above_second_spectrum_cutoff_matches_fe():
    beam = _square_beam(2.5)                        # very stocky: modes 4+ lie above ω_c
    exact = timoshenko_cantilever_frequencies(**beam, n_modes=10)
    omega_c = math.sqrt(beam["k_shear"] * beam["G"] * beam["A"] / (beam["rho"] * beam["I"]))
    assert np.count_nonzero(exact > omega_c) >= 6
    raw, extrapolated = _richardson_fe_frequencies(beam, n_elements=800, n_modes=10)
    assert np.max(np.abs(raw[:5] / exact[:5] - 1.0)) <= 1e-5
    # The ordered lists agree, so no mode of either spectrum was missed or duplicated.
    assert np.max(np.abs(extrapolated / exact - 1.0)) <= 1e-7


def test_timoshenko_tends_to_euler_bernoulli_as_h_squared():
    # The first correction is O((h/L)²). The next, O((h/L)⁴), bends the log–log slope by < 1e-3
    # over this range (by 3e-3 if L/h starts at 100).
    slenderness = np.array([200.0, 400.0, 800.0, 1600.0])
    rel = []
    for s in slenderness:
        beam = _square_beam(s)
        eb = euler_bernoulli_cantilever_frequencies(beam["E"] * beam["I"], beam["rho"] * beam["A"],
                                                    beam["L"], 5)
        rel.append(timoshenko_cantilever_frequencies(**beam, n_modes=5) / eb - 1.0)
    rel = np.array(rel)                                           # (4, 5)
    assert np.all(rel < 0.0)              # shear and rotary inertia can only lower frequencies
    for mode in range(5):
        slope = np.polyfit(np.log(1.0 / slenderness), np.log(-rel[:, mode]), 1)[0]
        assert abs(slope - 2.0) <= 1e-3
    beam = _square_beam(1e4)
    eb = euler_bernoulli_cantilever_frequencies(beam["E"] * beam["I"], beam["rho"] * beam["A"],
                                                beam["L"], 5)
    assert np.max(np.abs(timoshenko_cantilever_frequencies(**beam, n_modes=5) / eb - 1.0)) <= 1e-6


def test_timoshenko_root_scan_is_insensitive_to_its_resolution():
    # 20 modes of a stocky beam, where both spectra interleave. A scan with 2 samples per π of
    # phase (16× coarser than the default) must still find the same roots.
    beam = _square_beam(2.5)
    p = analytic._TimoshenkoParameters(g=beam["k_shear"] * beam["G"] * beam["A"] * beam["L"]**2
                                       / (beam["E"] * beam["I"]),
                                       q=beam["I"] / (beam["A"] * beam["L"]**2))
    fine = analytic._timoshenko_roots(p, 20)
    coarse = analytic._timoshenko_roots(p, 20, steps_per_pi=2)
    np.testing.assert_allclose(coarse, fine, rtol=1e-12)


def test_frequency_functions_reject_bad_input_with_named_argument():
    with pytest.raises(ValueError, match=r"n_modes must be a positive integer, got 0"):
        euler_bernoulli_cantilever_frequencies(1.0, 1.0, 1.0, 0)
    with pytest.raises(ValueError, match=r"G must be a finite positive number, got -1.0"):
        timoshenko_cantilever_frequencies(1.0, -1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 3)


# --------------------------------------------------------------------------------------------
# 3. Extensible elastica
# --------------------------------------------------------------------------------------------
# SPEC §7.11: k = PL²/EI -> (tip rotation, x/L, z/L), inextensible.
SPEC_ELASTICA = {2.0: (0.7817498, 0.839358279175, -0.493457480397),
                 4.0: (1.121239, 0.671058757753, -0.669964181278)}


def _inextensible_elastica_by_quadrature(k: float) -> tuple[float, float, float]:
    """(tip rotation α, x/L, z/L) of the inextensible elastica from its first integral.

    ``φ'' = −k cos φ`` with ``φ(0) = 0`` and ``φ'(1) = 0`` gives ``φ' = √(2k (sin α − sin φ))``.
    So ``√(2k) = ∫₀^α dφ/√(sin α − sin φ)``, ``x = √(2 sin α / k)`` and
    ``z = −∫₀^α sin φ dφ / φ'``. The substitution ``φ = α − u²`` removes the end singularity.
    """
    def integral(alpha: float, weight) -> float:
        def f(u: float) -> float:
            # (sin α − sin(α − u²))/u² = cos(α − u²/2) · sin(u²/2)/(u²/2), without cancellation.
            ratio = math.cos(alpha - 0.5 * u * u) * float(np.sinc(u * u / (2 * math.pi)))
            return 2.0 * weight(alpha - u * u) / math.sqrt(ratio)
        return quad(f, 0.0, math.sqrt(alpha), epsabs=0.0, epsrel=1e-13, limit=200)[0]

    alpha = brentq(lambda a: integral(a, lambda phi: 1.0) - math.sqrt(2.0 * k),
                   1e-6, 0.5 * math.pi - 1e-6, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    z_tip = -integral(alpha, math.sin) / math.sqrt(2.0 * k)
    return alpha, math.sqrt(2.0 * math.sin(alpha) / k), z_tip


@pytest.mark.parametrize("k", [2.0, 4.0])
def test_quadrature_elastica_confirms_spec_table(k):
    rotation, x, z = _inextensible_elastica_by_quadrature(k)
    spec_rotation, spec_x, spec_z = SPEC_ELASTICA[k]
    assert abs(x - spec_x) <= 1e-12 and abs(z - spec_z) <= 1e-12      # table has 12 decimals
    assert abs(rotation - spec_rotation) <= 5e-7                       # table is rounded


@pytest.mark.parametrize("k", [2.0, 4.0])
def test_elastica_inextensible_limit_matches_spec(k):
    L, EI = 2.0, 3.0
    stiff = 1e12 * EI / L**2
    result = extensible_elastica_cantilever(L, EI, stiff, stiff, k * EI / L**2)
    spec_rotation, spec_x, spec_z = SPEC_ELASTICA[k]
    assert abs(result["x_tip"] / (spec_x * L) - 1.0) <= 1e-9
    assert abs(result["z_tip"] / (spec_z * L) - 1.0) <= 1e-9
    assert abs(result["rotation_tip"] - spec_rotation) <= 5e-7 * max(1.0, spec_rotation)
    quad_rotation = _inextensible_elastica_by_quadrature(k)[0]
    assert abs(result["rotation_tip"] / quad_rotation - 1.0) <= 1e-9


def test_elastica_small_load_matches_linear_timoshenko_deflection():
    L, EI, EA, GA_s = 1.5, 2.0, 300.0, 80.0       # shear adds ~7 % to the deflection
    errors = []
    for k in (1e-3, 2e-3):
        P = k * EI / L**2
        linear = P * L**3 / (3 * EI) + P * L / GA_s
        errors.append(-extensible_elastica_cantilever(L, EI, EA, GA_s, P)["z_tip"] / linear - 1)
    assert abs(errors[0]) <= 2e-7
    # The leftover is the geometric nonlinearity, O(k²). That shows it is not a modelling error.
    assert abs(errors[1] / errors[0] - 4.0) <= 0.02


def test_elastica_tip_deflection_is_load_derivative_of_potential_energy():
    # At equilibrium dΠ/dP = z_tip (envelope theorem), Π = U(EI, EA, GA_s) + P z_tip. This checks
    # that the kinematics, the constitutive coupling and the energy belong together.
    L, EI, EA, GA_s = 1.5, 2.0, 300.0, 80.0
    P = 3.0 * EI / L**2

    def potential(load: float) -> float:
        return extensible_elastica_cantilever(L, EI, EA, GA_s, load)["potential_energy"]

    def central(h: float) -> float:
        return (potential(P + h) - potential(P - h)) / (2 * h)

    h = 1e-3 * P
    derivative = (4 * central(h) - central(2 * h)) / 3               # O(h⁴)
    z_tip = extensible_elastica_cantilever(L, EI, EA, GA_s, P)["z_tip"]
    assert abs(derivative / z_tip - 1.0) <= 1e-10


def test_elastica_shape_output_is_consistent_with_tip_and_statics():
    L, EI, EA, GA_s, P = 2.0, 5.0, 1e4, 2e3, 4.0
    r = extensible_elastica_cantilever(L, EI, EA, GA_s, P, n_nodes=51)
    assert r["arc_length"].shape == r["x"].shape == r["moment"].shape == (51,)
    np.testing.assert_allclose(r["shape"](L), [r["x_tip"], r["z_tip"], r["rotation_tip"]],
                               rtol=0, atol=1e-13)
    assert r["x"][0] == pytest.approx(0.0, abs=1e-14) and r["z"][0] == pytest.approx(0.0, abs=1e-14)
    # Moment of the dead load about each section: M(S) = P (x_tip − x(S)).
    np.testing.assert_allclose(r["moment"], P * (r["x_tip"] - r["x"]), rtol=0, atol=1e-9 * P * L)
    assert np.all(np.diff(r["rotation"]) > 0.0)


# --------------------------------------------------------------------------------------------
# 4. Roll-up
# --------------------------------------------------------------------------------------------
def _integrate_over_section(f, shape: str, size: tuple[float, ...]) -> float:
    """``∫ f(s) dA``, exact for polynomials in s up to degree 9. ``f`` is vectorized over s."""
    if shape == "rectangle":
        b, h = size
        x, w = np.polynomial.legendre.leggauss(5)
        return float(np.sum(w * f(0.5 * h * x)) * 0.5 * h * b)
    (r,) = size
    x, w = roots_chebyu(5)       # ∫ g(t) √(1 − t²) dt; the chord width is 2r√(1 − t²)
    return float(np.sum(w * f(r * x)) * 2.0 * r * r)


@pytest.mark.parametrize("shape,size", [("rectangle", (0.03, 0.05)), ("circle", (0.04,))])
def test_section_moments_match_quadrature(shape, size):
    moments = (section_moments_rectangle(*size) if shape == "rectangle"
               else section_moments_circle(*size))
    expected = np.array([_integrate_over_section(lambda s, k=k: s**k, shape, size)
                         for k in range(5)])
    # Odd moments are zero up to quadrature rounding, so compare with the scale size^(k+2).
    scale = max(size) ** (np.arange(5) + 2.0)
    assert np.all(np.abs(moments - expected) <= 1e-14 * scale)
    assert moments[1] == 0.0 and moments[3] == 0.0


@pytest.mark.parametrize("shape,size,M_over_EI_L", [("rectangle", (0.01, 0.02), 1.5 * math.pi),
                                                     ("circle", (0.015,), -0.7 * math.pi)])
def test_svk_rollup_is_a_stationary_minimum_by_section_quadrature(shape, size, M_over_EI_L):
    L, E = 1.2, 7e10
    moments = (section_moments_rectangle(*size) if shape == "rectangle"
               else section_moments_circle(*size))
    M = M_over_EI_L * E * moments[2] / L
    r = svk_rollup_tip(L, M, E, moments)

    def potential(stretch: float, theta: float) -> float:
        def density(s):
            return 0.5 * E * (0.5 * ((stretch - s * theta / L) ** 2 - 1.0)) ** 2
        return L * _integrate_over_section(density, shape, size) - M * theta

    def green(s):
        return 0.5 * ((r["stretch"] - s * r["rotation"] / L) ** 2 - 1.0)

    def stress_times_stretch(s):
        return E * green(s) * (r["stretch"] - s * r["rotation"] / L)

    # ∂Π/∂λ0 = L ∫ S11 λ dA and ∂Π/∂θ = −∫ S11 λ s dA − M. Both are compared with the size of
    # one of their terms.
    axial = L * _integrate_over_section(stress_times_stretch, shape, size)
    axial_scale = L * E * moments[0] * abs(r["stretch"] - 1.0)
    bending = -_integrate_over_section(lambda s: stress_times_stretch(s) * s, shape, size) - M
    assert abs(axial) <= 1e-11 * axial_scale
    assert abs(bending) <= 1e-12 * abs(M)
    pi0 = potential(r["stretch"], r["rotation"])
    for d_stretch, d_theta in [(1e-5, 0), (-1e-5, 0), (0, 1e-4), (0, -1e-4), (1e-5, 1e-4)]:
        assert potential(r["stretch"] + d_stretch, r["rotation"] + d_theta) > pi0
    # The tip lies on the circle of radius λ0 L/θ through the root, tangent to +x.
    radius = r["stretch"] * L / r["rotation"]
    assert math.hypot(r["x"], r["y"] - radius) == pytest.approx(abs(radius), rel=1e-14)


def test_svk_rollup_converges_to_linear_as_h_squared():
    L, E = 10.0, 1e7
    depth_ratio = np.array([1e-2, 5e-3, 2.5e-3, 1.25e-3])
    miss = []
    for ratio in depth_ratio:
        moments = section_moments_rectangle(0.5 * ratio * L, ratio * L)
        M = 0.8 * math.pi * E * moments[2] / L
        svk, lin = svk_rollup_tip(L, M, E, moments), linear_rollup_tip(L, M, E * moments[2])
        miss.append(math.hypot(svk["x"] - lin["x"], svk["y"] - lin["y"]) / L)
    slope = np.polyfit(np.log(depth_ratio), np.log(miss), 1)[0]
    assert abs(slope - 2.0) <= 5e-3
    assert miss[-1] <= 1e-5


def test_svk_full_circle_misses_root_as_spec_72_says():
    # SPEC §7.2: h/L = 1/100, M = 2πEI/L. The SVK bending stiffness softens as
    # 1 − 0.3 (κh)², so the end over-rotates by 2π·0.3(κh)² and the tip misses the root by
    # about 0.3 (κh)² L ≈ 1.18e-3 L. The next term is O((κh)⁴), about 0.4 % of that here.
    L, E, h = 10.0, 1e7, 0.1
    moments = section_moments_rectangle(h, h)
    r = svk_rollup_tip(L, 2 * math.pi * E * moments[2] / L, E, moments)
    miss = math.hypot(r["x"], r["y"]) / L
    predicted = 0.3 * (2 * math.pi * h / L) ** 2
    assert 1e-3 <= miss <= 1.5e-3
    assert abs(miss / predicted - 1.0) <= 5e-3
    assert r["rotation"] > 2 * math.pi and r["stretch"] < 1.0     # over-rolled, axis shortened


def test_linear_rollup_matches_spec_72_exact_positions():
    # SPEC §7.2: L = 10, 0.1 × 0.1, E = 1e7; tip at M/M_max = 0.25, 0.5, 0.75, 1.
    L, EI = 10.0, 1e7 * 0.1**4 / 12
    expected = [(6.3662, 6.3662), (0.0, 6.3662), (-2.1221, 2.1221), (0.0, 0.0)]
    for fraction, (x, y) in zip([0.25, 0.5, 0.75, 1.0], expected):
        tip = linear_rollup_tip(L, fraction * 2 * math.pi * EI / L, EI)
        assert tip["x"] == pytest.approx(x, abs=5e-5) and tip["y"] == pytest.approx(y, abs=5e-5)
    # θ → 0 needs no special case: a tiny moment gives the linear deflection ML²/(2EI).
    tiny = linear_rollup_tip(L, 1e-9, EI)
    assert tiny["x"] == pytest.approx(L, rel=1e-15)
    assert tiny["y"] == pytest.approx(1e-9 * L**2 / (2 * EI), rel=1e-12)
    zero = svk_rollup_tip(L, 0.0, 1e7, section_moments_rectangle(0.1, 0.1))
    assert (zero["x"], zero["y"], zero["stretch"]) == (L, 0.0, 1.0)
