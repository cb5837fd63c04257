"""Physical faults (issue 15, item 5): the scene's ``limits:`` — an actuator force beyond its bound
and a platform that passes through a singular configuration into another assembly mode — are
reported by the twin (status message, counters) and, with ``on_violation: stop``, stop it on the
last good state."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flexmb_core.errors import SceneError
from flexmb_core.faults import FaultMonitor
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene.loader import parse_yaml, scene_from_dict
from flexmb_io.twin import RunnerOptions, TwinRunner

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "stewart_platform_bars.yaml"


def _model(limits: dict | None):
    data = parse_yaml(SCENE.read_text())
    if limits is not None:
        data["limits"] = limits
    return compile_scene(scene_from_dict(data, source=str(SCENE)))


def _runner(limits: dict | None) -> TwinRunner:
    r = TwinRunner(_model(limits), options=RunnerOptions(command_hold="step"))
    r.start()
    return r


def _kick(r: TwinRunner) -> None:
    """A 1 mm step of leg1 within one step: the legs ring with kN forces (the static ones are ~20 N)."""
    lengths = r.model.actuators.l0.copy()
    lengths[0] += 1e-3
    assert r.command_array("/flexmb_twin/commands", lengths) is None


def test_the_reference_platform_is_one_stewart_platform_and_its_mirror_image_is_another_assembly_mode():
    m = _model(None)
    mon = FaultMonitor(m)
    [p] = mon.platforms
    assert p.name == "platform" and sorted(p.legs.tolist()) == list(range(6))
    assert mon.check(m.q0, np.zeros(6)) == []
    q = m.q0.copy()
    for ids in p.node_ids:                         # the platform reflected through the base plane
        q[ids[2]] = -q[ids[2]]
    [f] = mon.check(q, np.zeros(6))
    assert f.kind == "assembly_mode" and "platform 'platform' passed through a singular configuration" in f.detail


def test_force_beyond_the_limit_is_reported_and_stepping_goes_on():
    r = _runner({"max_actuator_force": 500.0})
    _kick(r)
    messages = [r.step() for _ in range(20)]
    assert all(o.advanced for o in messages)
    hit = [o.message for o in messages if o.message]
    assert hit and "limits violated at t =" in hit[0] and "beyond limits.max_actuator_force 500 N" in hit[0]
    assert r.counters.faults["actuator_force"] == len(hit) and not r.counters.stopped
    assert r.t == pytest.approx(0.02)


def test_stop_rolls_the_violating_step_back_and_holds_the_last_good_state():
    r = _runner({"max_actuator_force": 500.0, "on_violation": "stop"})
    _kick(r)
    outcomes = []
    for _ in range(20):
        before = r.sim.state.q.copy()
        outcomes.append(r.step())
        if not outcomes[-1].advanced:
            break
    last = outcomes[-1]
    assert not last.advanced and "(limits.on_violation: stop)" in last.message and "rolled back" in last.message
    assert np.array_equal(r.sim.state.q, before)            # the last good state is kept
    t_stop = r.t
    again = r.step()                                          # a stopped twin does not step on
    assert not again.advanced and again.message == last.message and r.t == t_stop
    assert np.abs(r.sample().actuator_forces).max() <= 500.0
    r.reset()                                                 # reset clears the stop
    assert r.step().advanced


def test_no_limits_section_costs_nothing_on_a_scene_without_a_stewart_platform():
    from flexmb_core.scene import load_scene

    m = compile_scene(load_scene(SCENE.parent / "boom_step.yaml"))
    assert not FaultMonitor(m).active


@pytest.mark.parametrize("limits, message", [
    ({"on_violation": "explode"}, "limits.on_violation: expected one of ['report', 'stop'], got 'explode'"),
    ({"max_actuator_force": -1.0}, "limits.max_actuator_force"),
    ({"max_force": 1.0}, "limits"),
    ({"singular_configurations": "maybe"}, "limits.singular_configurations: expected one of ['detect', 'ignore']"),
])
def test_bad_limits_are_refused_naming_the_key(limits, message):
    with pytest.raises(SceneError) as e:
        _model(limits)
    assert message in str(e.value)


def test_a_twin_from_whose_state_no_step_converges_stops_and_says_why():
    """A 0.5 m step of every leg in one Δt (step hold, no acceleration bound) throws the 1-element
    frame-leg twin into a state from which no step converges, even with 16 sub-steps. It used to
    retry that step for ever, its time frozen; it now stops after STUCK_AFTER failures in a row,
    with the reason, and a reset brings it back."""
    from flexmb_core.scene import load_scene
    from flexmb_io.twin import STUCK_AFTER

    path = SCENE.parent / "stewart_platform_1el.yaml"
    r = TwinRunner(compile_scene(load_scene(str(path))),
                   options=RunnerOptions(command_hold="step", max_command_accel=1e12))
    r.start()
    assert r.command_array("/c", list(r.schedule.lengths_at(0.0) + 0.5)) is None
    outcomes = [r.step() for _ in range(40)]
    failed = [o for o in outcomes if not o.advanced]
    assert r.counters.stopped and r.counters.failed_steps == STUCK_AFTER
    assert f"{STUCK_AFTER} steps in a row failed" in r.counters.stopped
    assert "no step converges from this state" in failed[-1].message
    t_stop = r.t
    assert not r.step().advanced and r.t == t_stop          # stays stopped, state kept
    r.reset()
    assert not r.counters.stopped and r.step().advanced
