"""The step guard (flexmb_core.solvers.guard): what it measures, and that a refused Newton root
goes through the on_unconverged policy with its reason — refused, stopped or flagged, never
silently accepted."""

import math

import numpy as np
import pytest

from builders import build, cantilever, free_beam
from flexmb_core.kernels.guard import conservative_moment_work
from flexmb_core.solvers.guard import SVK_LIMIT_STRETCH, StepGuard
from step_cases import spin_tumble


def _beam(elements=4):
    return build(cantilever(length=1.0, elements=elements, order=3, E=2e11, nu=0.0, rho=7850.0))


def _rotate(model, q, rot):
    """Rigid rotation of every position and section vector."""
    for n in range(len(model.node_names)):
        q[model.node_ydofs[n]] = rot @ q[model.node_ydofs[n]]
    for mem in model.members:
        for b in mem.vdofs.reshape(-1, 3):
            q[b] = rot @ q[b]


def test_reference_and_rigid_rotation_are_accepted():
    model, sim = _beam()
    g = StepGuard(model)
    q = model.q0.copy()
    assert g.orientation(q, np.ones(0)) == ("", "")
    c, s = math.cos(2.5), math.sin(2.5)
    _rotate(model, q, np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))
    assert g.orientation(q, np.ones(0)) == ("", "")


def test_a_section_turned_inside_out_is_refused():
    """Mirror V1 of one node: Green–Lagrange strain cannot tell (E(−F) = E(F) where V1 is the
    only change), det F < 0 can."""
    model, sim = _beam()
    g = StepGuard(model)
    q = model.q0.copy()
    mem = model.members[0]
    for k in (3, 4, 5, 6):                 # the nodes of element 2 (cubic: nodes 3…6)
        q[mem.vdofs[k, :3]] *= -1.0
    flag, why = g.orientation(q, np.ones(0))
    assert flag == "inverted"
    assert "det F = -1" in why and "'beam'" in why


def test_a_fibre_compressed_past_the_svk_limit_point_is_refused():
    model, sim = _beam()
    g = StepGuard(model)
    mem = model.members[0]
    for factor, expected in ((0.6, ""), (0.55, "svk_limit")):     # 1/√3 = 0.577
        q = model.q0.copy()
        for k in (3, 4, 5, 6):
            q[mem.vdofs[k, 3:]] *= factor      # V2 shrinks: det F = factor > 0
        assert g.orientation(q, np.ones(0))[0] == expected
    assert SVK_LIMIT_STRETCH == pytest.approx(1 / math.sqrt(3))


def test_conservative_moment_work_is_exact():
    """W = M·Δθ for a section vector turned by Δθ about the moment axis (|Δθ| < π)."""
    axes = np.array([[[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]])
    vd = np.array([[0, 1, 2]], dtype=np.int64)
    for dtheta in (0.3, -2.0, 3.0):
        q_p = np.array([math.cos(0.4), math.sin(0.4), 0.2])
        q = np.array([1.3 * math.cos(0.4 + dtheta), 1.3 * math.sin(0.4 + dtheta), -0.5])
        w = conservative_moment_work(q, q_p, vd, axes, np.array([7.0]), np.array([0.5]))
        assert w == pytest.approx(3.5 * dtheta, rel=1e-12)


def _folded_statics(policy):
    """Statics from a 0.5 m-off guess converges onto a folded beam (tests/verification/
    test_hard_cases.py::test_no_spurious_equilibrium_from_a_bad_initial_guess)."""
    d = cantilever(length=1.0, elements=8, order=3, E=2.0e11, nu=0.0, rho=7850.0,
                   section={"shape": "rectangle", "width": 0.01, "height": 0.02},
                   solver={"analysis": "static", "until": 1.0, "dt": 1.0, "tolerance": 1e-10,
                           "max_iterations": 100, "on_unconverged": policy})
    d["loads"]["gravity"] = [0.0, 0.0, -9.81]
    model, sim = build(d)
    rng = np.random.default_rng(1)
    q = sim.state.q
    for b in model.node_ydofs:
        x = model.q0[b[0]]
        q[b] += 0.5 * np.array([0.0, 0.3 * x, x * x])
    q[model.free] += 0.01 * rng.standard_normal(model.nfree)
    return model, sim


def test_refused_root_with_policy_stop_restores_the_state():
    model, sim = _folded_statics("stop")
    q_bad = sim.state.q.copy()
    res = sim.initialize()
    assert not res.converged and res.guard == "inverted" and res.substeps == 1
    assert res.message.startswith("step guard: inverted frame section")
    assert np.array_equal(sim.state.q, q_bad)
    assert sim._static.guard.rejections == 1


def test_refused_root_with_policy_accept_flagged_keeps_it_flagged():
    model, sim = _folded_statics("accept_flagged")
    res = sim.initialize()
    assert not res.converged and res.guard == "inverted"
    assert res.strain > 0.0                                  # the flagged state's energy is reported
    assert StepGuard(model).orientation(sim.state.q, sim.state.lam)[0] == "inverted"


def _tumbling_trapezoidal(policy):
    """The free tumbling beam of the hard cases under the trapezoidal rule at Δt = 1 ms: Newton
    converges onto a spurious root at step 126."""
    d = free_beam(integrator="newmark", dt=1e-3, tolerance=1e-10, on_unconverged=policy)
    model, sim = build(d)
    spin_tumble(model, sim)
    sim.initialize()
    return model, sim


def test_dynamic_refusal_is_split_and_recorded():
    """Policy substep: the spurious root of step 126 is refused and the step split; the result
    keeps the guard's flag and reason next to the split, the summary counts the step, and the
    accepted energy stays at the start's."""
    model, sim = _tumbling_trapezoidal("substep")
    e0 = sim.last.total_energy
    while sim.stats.steps < 126:
        res = sim.step()
        assert res.converged
        if sim.stats.steps < 126:
            assert not res.guard
    assert res.guard in ("inverted", "energy") and res.substeps > 1
    assert res.message.startswith("split into") and "step guard" in res.message
    assert sim.summary()["guard_rejected_steps"] == 1
    assert abs(res.total_energy / e0 - 1.0) < 1e-2
