"""Static large-deflection benchmarks (SPEC §7.2, §7.3, §7.11) against closed forms, with the
Saint-Venant–Kirchhoff effects accounted for ("compare like with like")."""

import math

import numpy as np
import pytest

from builders import build, cantilever
from flexmb_core.verification.analytic import (extensible_elastica_cantilever, linear_rollup_tip,
                                               svk_rollup_tip_relaxed_section)


def static_history(d):
    """Run a static scene; return [(t, tip)] at every load step and the iteration counts."""
    model, sim = build(d)
    sim.initialize()
    hist, iters = [], []
    while sim.state.t < d["solver"]["until"] - 1e-12:
        res = sim.step()
        assert res.converged
        iters.append(res.iterations)
        hist.append((sim.state.t, np.array(sim.outputs()["tip"])))
    return hist, iters


def rollup(length, h, elements, steps=20, E=1e7, integration="reduced"):
    ei = E * h**4 / 12
    m_max = 2 * math.pi * ei / length
    d = cantilever(length=length, elements=elements, order=3, E=E, nu=0.0, rho=1.0,
                   section={"shape": "rectangle", "width": h, "height": h},
                   moments={"end": {"node": "tip", "member": "beam", "moment": [0, 0, m_max],
                                    "signal": {"kind": "ramp", "start": 0, "end": 1, "duration": 1.0}}},
                   solver={"analysis": "static", "until": 1.0, "dt": 1.0 / steps, "tolerance": 1e-12,
                           "max_iterations": 40})
    d["members"]["beam"]["integration"] = integration
    hist, iters = static_history(d)
    return hist, m_max, ei, iters


def test_rollup_thin_section_closes_the_circle():
    """h/L = 1e-3: SVK softening is ~1e-7, so the linear closed form applies; 10 cubic elements."""
    length, h = 10.0, 0.01
    hist, m_max, ei, _ = rollup(length, h, 10)
    for t, tip in hist[4::5]:
        exact = linear_rollup_tip(length, t * m_max, ei)
        err = math.hypot(tip[0] - exact["x"], tip[1] - exact["y"]) / length
        assert err < 1e-4, f"M/Mmax = {t:.2f}: tip error {err:.2e}·L"
    assert math.hypot(*hist[-1][1][:2]) / length < 1e-4


def test_rollup_thick_section_follows_svk():
    """h/L = 1e-2: bending softens by O((κh)²), the tip misses the root by 1.8e-3·L; the FE must
    match the SVK prediction (with the section free to shrink, as the positional frame is)."""
    length, h = 10.0, 0.1
    hist, m_max, ei, _ = rollup(length, h, 10)
    for t, tip in hist[4::5]:
        svk = svk_rollup_tip_relaxed_section(length, t * m_max, 1e7, h, h)
        err = math.hypot(tip[0] - svk["x"], tip[1] - svk["y"]) / length
        assert err < 1e-5, f"M/Mmax = {t:.2f}: tip error vs SVK {err:.2e}·L"
    gap = math.hypot(*hist[-1][1][:2]) / length
    assert 1.5e-3 < gap < 2.2e-3   # the SVK effect is real and resolved, not noise


def test_rollup_full_integration_locks_reduced_does_not():
    """Same thin roll-up with the full (p + 2) axial rule: membrane locking stiffens the arc."""
    length, h = 10.0, 0.01
    hist_r, *_ = rollup(length, h, 10, integration="reduced")
    hist_f, *_ = rollup(length, h, 10, integration="full")
    assert math.hypot(*hist_f[-1][1][:2]) / length > 1e-2 > 1e3 * math.hypot(*hist_r[-1][1][:2]) / length * 1e-1


def _elastica_fe(radius, elements, steps=4):
    E, nu, length = 200e9, 0.3, 1.0
    area, inertia = math.pi * radius**2, math.pi * radius**4 / 4
    p = 2 * E * inertia / length**2                       # k = PL²/EI = 2
    d = cantilever(length=length, elements=elements, order=3, E=E, nu=nu, rho=7850.0,
                   section={"shape": "circle", "radius": radius},
                   forces={"p": {"node": "tip", "force": [0, 0, -p], "signal": {"kind": "ramp", "duration": 1.0}}},
                   solver={"analysis": "static", "until": 1.0, "dt": 1.0 / steps, "tolerance": 1e-12})
    hist, _ = static_history(d)
    g = E / (2 * (1 + nu))
    ks = 6 * (1 + nu) / (7 + 6 * nu)
    ref = extensible_elastica_cantilever(length, E * inertia, E * area, ks * g * area, p)
    tip = hist[-1][1]
    return math.hypot(tip[0] - ref["x_tip"], tip[2] - ref["z_tip"]) / length


def test_large_deflection_cantilever_matches_extensible_elastica():
    """k = 2, slender rod (r/L = 2e-3) so that SVK bending softening (∝ (κr)²) stays ≪ 1e-5·L."""
    assert _elastica_fe(0.002, 8) < 1e-5


def test_elastica_gap_of_thick_rod_is_svk_softening():
    """The remaining gap to the linear-law elastica grows as r² (SVK softening ∝ (κr)²)."""
    g5 = _elastica_fe(0.005, 8)
    g2 = _elastica_fe(0.002, 8)
    assert 1e-5 < g5 < 3e-5
    assert g5 / g2 == pytest.approx((5 / 2) ** 2, rel=0.25)


def test_elastica_mesh_convergence_rate():
    """Tip error of the r = 2 mm rod against the converged FE tip with 1, 2 and 3 elements:
    reduced-integrated cubic elements converge at least at order p + 1 = 4."""
    # Compare with a converged FE reference (24 elements) so that only discretization is measured.
    E, nu, length, radius = 200e9, 0.3, 1.0, 0.002
    p = 2 * E * math.pi * radius**4 / 4 / length**2

    def tip(n):
        d = cantilever(length=length, elements=n, order=3, E=E, nu=nu, rho=7850.0,
                       section={"shape": "circle", "radius": radius},
                       forces={"p": {"node": "tip", "force": [0, 0, -p], "signal": {"kind": "ramp", "duration": 1.0}}},
                       solver={"analysis": "static", "until": 1.0, "dt": 0.25, "tolerance": 1e-12})
        return static_history(d)[0][-1][1]
    ref = tip(24)
    ns = (1, 2, 3)
    errs = [np.linalg.norm(tip(n) - ref) for n in ns]
    rate = np.polyfit(np.log(1.0 / np.array(ns)), np.log(errs), 1)[0]
    assert rate > 3.8, f"observed rate {rate:.2f} (errors {errs})"


def test_45_degree_bend():
    """Bathe–Bolourchi 45° bend, P = 600 (SPEC §7.3): converged tip (15.685, 47.143, 53.477);
    literature (Simo & Vu-Quoc; Bathe & Bolourchi) within 0.15."""
    r = 100.0
    d = cantilever(elements=8, order=3, E=1e7, nu=0.0, rho=1.0,
                   section={"shape": "rectangle", "width": 1.0, "height": 1.0},
                   section_extra={"torsion_constant": 1.0 / 6.0, "shear_factor": 5.0 / 6.0},
                   arc_center=(r, 0.0, 0.0), tip=[r - r * math.cos(math.pi / 4), r * math.sin(math.pi / 4), 0.0],
                   up=(0, 0, 1),
                   forces={"p": {"node": "tip", "force": [0, 0, 600.0], "signal": {"kind": "ramp", "duration": 1.0}}},
                   solver={"analysis": "static", "until": 1.0, "dt": 0.1, "tolerance": 1e-11})
    hist, iters = static_history(d)
    tip = hist[-1][1]
    assert np.abs(tip - [15.685, 47.143, 53.477]).max() < 5e-3
    assert np.linalg.norm(tip - [15.79, 47.23, 53.37]) < 0.2
    assert np.linalg.norm(tip - [15.9, 47.2, 53.4]) < 0.25
    assert max(iters) <= 12
