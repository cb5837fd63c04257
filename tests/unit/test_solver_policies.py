"""Newton's convergence test scales itself; failed steps are split, stopped or flagged — never
silently accepted."""

import math

import numpy as np
import pytest

from builders import build, cantilever
from flexmb_core.errors import ConvergenceError


@pytest.mark.parametrize("E", [2.0e11, 1.0e6])
def test_same_tolerance_for_steel_and_rubber(E):
    """Loads scaled with E (same k = PL²/EI): same deflection, same iteration counts, same tolerance."""
    inertia = math.pi * 0.01**4 / 4
    p = 1.5 * E * inertia
    d = cantilever(length=1.0, elements=4, order=3, E=E, nu=0.45, rho=1000.0,
                   section={"shape": "circle", "radius": 0.01},
                   forces={"f": {"node": "tip", "force": [0, 0, -p], "signal": {"kind": "ramp", "duration": 1.0}}},
                   solver={"analysis": "static", "until": 1.0, "dt": 0.25})
    _, sim = build(d)
    sim.initialize()
    sim.run(1.0)
    s = sim.summary()
    assert s["unconverged_steps"] == 0
    assert s["newton_iterations_max"] <= 8
    assert s["max_relative_residual"] < 1e-8
    tip = sim.outputs()["tip"]
    assert tip[2] == pytest.approx(-0.4, abs=0.05)      # the same large deflection for both


def _one_shot_rollup(policy, levels):
    e, h, length = 1e7, 0.1, 10.0
    m = 2 * math.pi * e * h**4 / 12 / length
    d = cantilever(length=length, elements=10, order=3, E=e, nu=0.0, rho=1.0,
                   section={"shape": "rectangle", "width": h, "height": h},
                   moments={"end": {"node": "tip", "member": "beam", "moment": [0, 0, m],
                                    "signal": {"kind": "ramp", "duration": 1.0}}},
                   solver={"analysis": "static", "until": 1.0, "dt": 1.0, "max_iterations": 12,
                           "on_unconverged": policy, "max_substep_levels": levels})
    return build(d)


def test_failed_increment_is_split_and_reported():
    """A full-circle roll-up in one increment does not converge in 12 iterations; bisection does."""
    _, sim = _one_shot_rollup("substep", 6)
    sim.initialize()
    res = sim.step()
    assert res.converged and res.substeps > 1
    assert "split into" in res.message
    assert math.hypot(*sim.outputs()["tip"][:2]) < 0.03
    assert sim.summary()["substepped_steps"] == 1


def test_failed_step_raises_and_keeps_the_state():
    model, sim = _one_shot_rollup("stop", 0)
    sim.initialize()
    q_before = sim.state.q.copy()
    with pytest.raises(ConvergenceError, match="did not converge"):
        sim.step()
    assert np.array_equal(sim.state.q, q_before)
    assert sim.summary()["unconverged_steps"] == 1


def test_accept_flagged_returns_a_flagged_result():
    d = cantilever(length=1.0, elements=4, order=3, E=2e11, nu=0.3, rho=7850.0,
                   section={"shape": "circle", "radius": 0.005},
                   forces={"f": {"node": "tip", "force": [0, 0, -400.0]}},
                   solver={"analysis": "dynamic", "dt": 0.05, "max_iterations": 1,
                           "on_unconverged": "accept_flagged"})
    _, sim = build(d)
    sim.initialize()
    res = sim.step()
    assert not res.converged and "no convergence in 1 iterations" in res.message
    assert sim.summary()["unconverged_steps"] == 1


def test_initial_static_equilibrium_starts_the_twin_at_rest():
    """Under constant gravity, a run started from the static equilibrium stays put; from the
    unloaded reference it swings (the jolt the Stewart benchmark found at t = 0)."""
    def run(initial_state):
        d = cantilever(length=1.0, elements=4, order=3, E=2e11, nu=0.3, rho=7850.0,
                       section={"shape": "circle", "radius": 0.005},
                       solver={"analysis": "dynamic", "dt": 1e-3, "until": 0.1, "initial_state": initial_state})
        d["loads"]["gravity"] = [0.0, 0.0, -9.81]
        _, sim = build(d)
        sim.initialize()
        kin = []
        sim.run(0.1, callback=lambda s, r: kin.append(r.kinetic))
        return max(kin), sim.last.strain

    k_static, u_static = run("static")
    k_rest, _ = run("rest")
    assert k_rest > 1e-4 * u_static        # the swing from the unloaded geometry
    assert k_static < 1e-12 * u_static     # at rest in equilibrium


def test_statics_follows_the_same_policy_as_dynamics():
    """accept_flagged in statics: no bisection, the flagged iterate is returned and counted."""
    _, sim = _one_shot_rollup("accept_flagged", 6)
    sim.initialize()
    res = sim.step()
    assert not res.converged and res.substeps == 1
    assert "no convergence in 12 iterations" in res.message
    assert sim.summary()["unconverged_steps"] == 1
