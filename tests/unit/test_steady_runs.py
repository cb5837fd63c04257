"""``Simulator.run`` without a callback runs the steps of a run without servos and driven
supports in one numba call per batch (``integrators/fast.py: model_steps``): when its commands do
not change, all the steady steps once the loads no longer change; otherwise 256 at a time with
their loads and the scene's commanded lengths formed beforehand. Those runs must be the
step-by-step run, bit for bit: the state, the step data (held tangent, stretch history, the
guard's ledger), the statistics and the last result — including the steps whose first attempt
fails inside a batch and that the policy then splits or stops at."""

import copy
import dataclasses

import numpy as np
import pytest

import step_cases as sc
from flexmb_core.errors import ConvergenceError
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene.loader import parse_yaml, scene_from_dict
from flexmb_core.simulator import Simulator

WALL_KEYS = {"wall_time_s", "rtf", "steps_per_s"}


def _both(make, until, spy):
    """The run of ``make()`` to ``until`` by ``run`` without a callback, and step by step
    (a callback makes ``run`` take every step in Python)."""
    batched, stepped = make(), make()
    spy(batched)
    errors = []
    for sim, cb in ((batched, None), (stepped, lambda s, r: None)):
        try:
            sim.run(until, callback=cb)
            errors.append(None)
        except ConvergenceError as exc:
            errors.append(str(exc))
    return batched, stepped, errors


def _calls(sim):
    """Record (time, steps asked, accepted, the last settled) of each batch of ``sim``."""
    calls = []
    steps = sim._dynamic.steps

    def counted(state, dt, lam, count):
        t = state.t
        done, res, tally, settled = steps(state, dt, lam, count)
        calls.append((round(t, 9), count, done, settled))
        return done, res, tally, settled
    sim._dynamic.steps = counted
    return calls


def _assert_same(a: Simulator, b: Simulator):
    assert np.array_equal(a.data.buf, b.data.buf, equal_nan=True)
    sa, sb = a.summary(), b.summary()
    assert {k: v for k, v in sa.items() if k not in WALL_KEYS} == {k: v for k, v in sb.items() if k not in WALL_KEYS}
    assert a.last == b.last


def _b1(**solver):
    d = sc.b1()
    d["solver"].update(solver)
    return lambda: sc.dict_sim(copy.deepcopy(d), lambda m, s: s.initialize())


def test_batches_equal_the_step_by_step_run():
    calls = []
    a, b, errors = _both(_b1(until=0.5), 0.5, lambda s: calls.append(_calls(s)))
    assert errors == [None, None]
    _assert_same(a, b)
    (batches,) = calls
    # 256 steps with their loads tabulated (the ramp ends at 0.1 s), then the steady rest but the
    # last one or two steps (one step short of until, on the float times), which go on their own
    assert batches[0] == (0.0, 499, 256, False) and len(batches) == 2
    t, asked, done, settled = batches[1]
    assert t == 0.256 and asked == done >= 242 and not settled and a.stats.steps == 500


def test_moment_loads_ramp_step_by_step_then_batch():
    """Moment loads' scales are set per step outside f_ext: no table while they ramp."""
    calls = []

    def make():
        d = sc.b1()
        sc.moments(True)(d)
        d["solver"]["until"] = 0.3
        return sc.dict_sim(d, lambda m, s: s.initialize())
    a, b, errors = _both(make, 0.3, lambda s: calls.append(_calls(s)))
    assert errors == [None, None]
    _assert_same(a, b)
    (batches,) = calls
    assert len(batches) == 1 and batches[0][0] >= 0.1 and batches[0][2] > 150


def test_a_failed_attempt_inside_a_batch_is_split_as_step_by_step():
    """Six Newton iterations at most: a few steps (t = 0.016 s in the ramp, 0.371 … 0.43 s after
    it) need more, fail their attempt and are split into sub-steps; the batches resume after each."""
    calls = []
    a, b, errors = _both(_b1(until=0.5, max_iterations=6), 0.5, lambda s: calls.append(_calls(s)))
    assert errors == [None, None]
    _assert_same(a, b)
    (batches,) = calls
    assert sum(settled for *_, settled in batches) >= 3
    assert a.stats.substepped_steps >= 3


def test_a_failed_step_inside_a_batch_stops_the_run_at_the_same_step():
    """The same run with the policy ``stop`` from 0.3 s on: it stops at t = 0.371 s, inside a
    batch, with the message and the state of the step-by-step run."""
    calls = []
    make = _b1(until=0.5, max_iterations=6)

    def stop_after_ramp():
        sim = make()
        sim.run(0.3, callback=lambda s, r: None)
        sim.spec = sim._dynamic.spec = dataclasses.replace(sim.spec, on_unconverged="stop")
        return sim
    a, b, errors = _both(stop_after_ramp, 0.5, lambda s: calls.append(_calls(s)))
    assert errors[0] is not None and errors[0] == errors[1]
    assert errors[0].startswith("step to t = 0.371 s did not converge: no convergence in 6 iterations")
    _assert_same(a, b)
    assert calls[0] and calls[0][-1][3]


def test_held_commands_run_in_one_call():
    """The bar-leg twin with lengths held by set_commands: steady, all the steps in one call."""
    def held():
        sim = sc.scene_sim("stewart_platform_bars")
        sim.initialize()
        sim.set_commands(sim.model.actuators.l0 * 1.002)
        return sim
    calls = []
    a, b, errors = _both(held, 0.2, lambda s: calls.append(_calls(s)))
    assert errors == [None, None]
    _assert_same(a, b)
    assert calls[0] and sum(done for _, _, done, _ in calls[0]) > 150


def _scene(name, **solver):
    def make():
        sim = sc.scene_sim(name, solver or None)
        sim.initialize()
        return sim
    return make


@pytest.mark.parametrize("name", ["stewart_platform_bars", "stewart_platform_1el"])
def test_scene_commands_run_in_batches_of_their_tabulated_lengths(name):
    """The scene's command program moves the legs at every step: 256 steps per call, their
    commanded stretches formed beforehand; bars and damped frame legs (whose stretch rates are
    the kernel's backward differences) give the step-by-step run bit for bit."""
    calls = []
    a, b, errors = _both(_scene(name), 0.6, lambda s: calls.append(_calls(s)))
    assert errors == [None, None]
    _assert_same(a, b)
    assert [c[1:3] for c in calls[0][:2]] == [(256, 256), (256, 256)]
    assert a.stats.steps == 600 and np.any(a.state.lam != 1.0)      # the legs moved


def test_a_failed_attempt_inside_a_commanded_batch_is_split_at_its_own_lengths():
    """The bar-leg twin dropped from rest (its weight not yet carried) with one Newton iteration at
    most: 76 of its first 300 steps need more, fail inside a batch and are split at the stretches
    of that step (not of the batch's first)."""
    calls = []
    a, b, errors = _both(_scene("stewart_platform_bars", max_iterations=1, initial_state="rest"), 0.3,
                         lambda s: calls.append(_calls(s)))
    assert errors == [None, None]
    _assert_same(a, b)
    assert sum(settled for *_, settled in calls[0]) >= 50 and a.stats.substepped_steps >= 50


def test_servo_runs_go_step_by_step():
    """A servo advances in Python at every step: no batch."""
    data = parse_yaml((sc.SCENES / "stewart_platform_bars.yaml").read_text())
    data["members"]["leg1"]["actuator"]["servo"] = {"bandwidth_hz": 15.0, "damping_ratio": 0.8,   # every leg
                                                     "max_rate": 0.5, "max_accel": 10.0}
    sim = Simulator(compile_scene(scene_from_dict(data, source="stewart_servo.yaml")))
    sim.initialize()
    spy = _calls(sim)
    sim.run(0.05)
    assert spy == [] and sim.stats.steps == 50


@pytest.mark.parametrize("until", [0.4003, 0.45])
def test_the_last_step_lands_on_until(until):
    a, b, errors = _both(_b1(until=until), until, lambda s: None)
    assert errors == [None, None]
    _assert_same(a, b)
    assert a.state.t == pytest.approx(until, abs=1e-12)


@pytest.mark.parametrize("every", [1, 7, 300])
def test_a_callback_every_k_steps_sees_the_step_by_step_states(every):
    """``run(until, callback, every=k)``: the callback after every k-th step and after the last
    one, at the states of the step-by-step run; the steps between run in batches (k > 2)."""
    seen = {}

    def record_all(s, r):
        seen[s.stats.steps] = (s.state.t, s.data.buf.copy(), r)
    stepped = _scene("stewart_platform_1el")()
    stepped.run(0.1, callback=record_all)
    batched = _scene("stewart_platform_1el")()
    calls = _calls(batched)
    got = []
    batched.run(0.1, callback=lambda s, r: got.append((s.stats.steps, s.state.t, s.data.buf.copy(), r)), every=every)
    assert [n for n, *_ in got] == sorted(set(list(range(every, 100, every)) + [100]))
    for n, t, buf, r in got:
        t_ref, buf_ref, r_ref = seen[n]
        assert t == t_ref and np.array_equal(buf, buf_ref, equal_nan=True) and r == r_ref
    _assert_same(batched, stepped)
    assert (calls == []) == (every <= 2)


def test_every_is_a_whole_number_of_steps():
    sim = _scene("stewart_platform_bars")()
    for bad in (0, 2.5, -1):
        with pytest.raises(ValueError, match="every must be a whole number of steps ≥ 1"):
            sim.run(0.01, callback=lambda s, r: None, every=bad)
