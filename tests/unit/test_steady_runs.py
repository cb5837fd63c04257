"""``Simulator.run`` without a callback runs the steps of a run whose commands do not change and
that has no driven supports in one numba call per batch (``integrators/fast.py: model_steps``):
all the steady steps once the loads no longer change, 256 at a time with their loads formed
beforehand while they do. Those runs must be the step-by-step run, bit for bit: the state, the
step data (held tangent, stretch history, the guard's ledger), the statistics and the last result
— including the steps whose first attempt fails inside a batch and that the policy then splits or
stops at."""

import copy
import dataclasses

import numpy as np
import pytest

import step_cases as sc
from flexmb_core.errors import ConvergenceError
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


def test_held_commands_run_in_one_call_and_scene_commands_step_by_step():
    """The bar-leg twin: lengths held by set_commands are steady; the scene's own command
    program moves them at every step, so its run goes step by step."""
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

    def scene():
        sim = sc.scene_sim("stewart_platform_bars")
        sim.initialize()
        return sim
    moving = scene()
    spy = _calls(moving)
    moving.run(0.05)
    assert spy == [] and moving.stats.steps == 50


@pytest.mark.parametrize("until", [0.4003, 0.45])
def test_the_last_step_lands_on_until(until):
    a, b, errors = _both(_b1(until=until), until, lambda s: None)
    assert errors == [None, None]
    _assert_same(a, b)
    assert a.state.t == pytest.approx(until, abs=1e-12)
