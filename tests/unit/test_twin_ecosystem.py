"""Issue 14 without DDS: JointState commands take the path of the other command topics, a reset
repeats the start bit for bit, the stepper's hold / step N / reset, frame ids and prefixes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_core.simulator import Simulator
from flexmb_io import messages as M
from flexmb_io.realtime import Stepper, StepperConfig
from flexmb_io.twin import RunnerOptions, TwinRunner, apply_message

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "stewart_platform_bars.yaml"
TOPIC = "/flexmb_twin/joint_commands"


@pytest.fixture(scope="module")
def stewart():
    model = compile_scene(load_scene(str(SCENE)))
    return model, Simulator(model)       # the simulator only for the scene's command law L(t)


def _joint_state(names, position, velocity=(), effort=(), t=0.0) -> dict:
    return {"header": M.header(t), "name": list(names), "position": [float(x) for x in position],
            "velocity": [float(x) for x in velocity], "effort": [float(x) for x in effort]}


def _history(runner, commands, send) -> np.ndarray:
    """(steps, ndof) positions after each step, ``send(runner, lengths)`` applying each command."""
    out = []
    for lengths in commands:
        assert send(runner, lengths) is None
        runner.step()
        out.append(runner.sim.state.q.copy())
    return np.array(out)


def _law(program, runner, steps):
    return [program.command_lengths((k + 1) * runner.dt) for k in range(steps)]


def test_joint_state_commands_equal_float64_commands_in_any_order(stewart):
    model, program = stewart
    names = list(model.actuators.names)
    order = [3, 0, 5, 1, 4, 2]
    a, b = TwinRunner(model), TwinRunner(model)
    a.start()
    b.start()
    law = _law(program, a, 200)
    qa = _history(a, law, lambda r, L: r.command_array("/flexmb_twin/commands", L))
    qb = _history(b, law, lambda r, L: apply_message(
        r, "joint_commands", TOPIC, _joint_state([names[i] for i in order], [L[i] for i in order])))
    assert np.array_equal(qa, qb)
    assert a.sample().actuator_commands.tolist() == b.sample().actuator_commands.tolist()


def test_joint_state_velocity_is_the_commanded_rate(stewart):
    model, program = stewart
    names = list(model.actuators.names)
    a, b = TwinRunner(model), TwinRunner(model)
    a.start()
    b.start()
    L, v = program.command_lengths(0.0) + 0.001, np.full(6, 0.01)
    assert a.command_named("/x", names, L, v, 0.0) is None
    assert apply_message(b, "joint_commands", TOPIC, _joint_state(names, L, v)) is None
    for r in (a, b):
        for _ in range(50):
            r.step()
    assert np.array_equal(a.sim.state.q, b.sim.state.q)


def test_joint_state_subset_keeps_the_other_actuators(stewart):
    model, program = stewart
    r = TwinRunner(model)
    r.start()
    before = r.sample().actuator_commands.copy()
    assert apply_message(r, "joint_commands", TOPIC, _joint_state(["leg2"], [before[1] + 0.01])) is None
    for _ in range(600):
        r.step()
    after = r.sample().actuator_commands
    assert after[1] == pytest.approx(before[1] + 0.01, abs=1e-12)
    assert np.array_equal(np.delete(after, 1), np.delete(before, 1))


@pytest.mark.parametrize("msg,kind,text", [
    (_joint_state(["leg1", "no_such_leg"], [1.0, 1.0]), "unknown_name", "unknown actuator names [no_such_leg]"),
    (_joint_state(["leg1"], [1.0], effort=[5.0]), "size", "effort must be empty"),
    (_joint_state(["leg1"], [], velocity=[0.1]), "size", "velocity-only command is not supported"),
    (_joint_state(["leg1", "leg2"], [1.0]), "size", "2 names but 1 lengths"),
    (_joint_state(["leg1"], [2.5]), "stroke", "leg1=2.5 m (stroke [0.65, 1.65] m)"),
])
def test_bad_joint_state_commands_are_rejected_naming_topic_and_value(stewart, msg, kind, text):
    r = TwinRunner(stewart[0])
    r.start()
    rej = apply_message(r, "joint_commands", TOPIC, msg)
    assert rej is not None and rej.kind == kind
    assert str(rej).startswith(f"{TOPIC}: rejected ({kind}): ") and text in str(rej)
    assert r.counters.rejections == {kind: 1}


def test_joint_state_stamps_only_with_the_option(stewart):
    """topic_based_ros2_control stamps with its own clock (wall time without use_sim_time): ignored by
    default, checked like an ActuatorCommand's with joint_command_stamps."""
    model, program = stewart
    L = program.command_lengths(0.0)
    wall_stamped = _joint_state(model.actuators.names, L, t=1.7e9)
    r = TwinRunner(model)
    r.start()
    assert apply_message(r, "joint_commands", TOPIC, wall_stamped) is None
    s = TwinRunner(model, options=RunnerOptions(joint_command_stamps=True))
    s.start()
    rej = apply_message(s, "joint_commands", TOPIC, wall_stamped)
    assert rej is not None and rej.kind == "future"


def test_reset_repeats_the_start_bit_for_bit(stewart):
    model, program = stewart
    r = TwinRunner(model)
    r.start()
    law = _law(program, r, 150)
    send = (lambda rr, L: rr.command_array("/flexmb_twin/commands", L))
    first = _history(r, law, send)
    assert r.t > 0.1 and r.counters.steps == 150
    r.reset()
    assert r.t == 0.0 and r.counters.steps == 0 and r.schedule.accepted == 0
    second = _history(r, law, send)
    assert np.array_equal(first, second)


def _stepper(model, mode="lockstep"):
    runner = TwinRunner(model)
    runner.start()
    events = []
    st = Stepper(runner, StepperConfig(mode=mode, publish_every=10, clock_every=5), lambda: events.append(1))
    return runner, st


def test_stepper_hold_step_n_and_reset_without_the_thread(stewart):
    model, program = stewart
    runner, st = _stepper(model)
    st.hold()
    # a command while held is applied (recorded as an event) but owes no step
    assert st.submit("/t", "commands", {"data": list(program.command_lengths(0.0) + 0.001)}, 0.0) is None
    assert runner.counters.steps == 0 and st._pending == 0
    assert runner.schedule.accepted == 1
    done, message = st.step_n(25)
    assert done == 25 and message == "" and runner.t == pytest.approx(25 * runner.dt, abs=1e-15)
    kinds = [ev[0] for ev in st.outbox]
    # the held state with its /clock, the command, then /clock every 5 steps; states: the first
    # that uses the command (publish_on_command), every 10th and the last (acknowledged)
    assert kinds[:3] == ["out", "clock", "cmd"] and st.slots[st.outbox[0][1]].state.t == 0.0
    assert kinds.count("cmd") == 1 and kinds.count("clock") == 1 + 5 and kinds.count("out") == 1 + 4
    last = st.slots[st.outbox[-2][1]] if st.outbox[-1][0] == "clock" else st.slots[st.outbox[-1][1]]
    assert last.ack and last.due and last.state.t == runner.t
    st.reset()
    assert runner.t == 0.0 and st._n == 0
    assert st.outbox[-2][0] == "out" and st.outbox[-1] == ("clock", 0.0)


def test_a_realtime_stepper_maps_a_commands_reception_onto_the_twins_time(stewart):
    """A bare command's arrival is the twin time whose deadline its reception is: state n stands for
    the wall time t0 + nΔt, so a reception 1.3 ms before that is the twin's t − 1.3 ms, whatever
    step the twin is at (its own time stands still while the stepping thread is late). Rounded to
    the ns the recording keeps; None where it is the twin's time, and in lockstep."""
    import time

    model, program = stewart
    runner, st = _stepper(model, mode="realtime")
    st.hold()
    st.step_n(5)
    st._held, st._running = False, True          # as the realtime loop has it (not started here)
    st._t0 = time.perf_counter() + 10.0          # state 0's wall time far ahead: no step runs on submit
    command = {"data": list(program.command_lengths(0.0))}
    wall_5 = st._t0 + 5 * runner.dt
    st.submit("/t", "commands", command, wall_5 - 1.3e-3)
    ev = st.outbox[-1]
    assert ev[0] == "cmd" and ev[4] == runner.t and ev[5] is None
    assert ev[8] == round((runner.t - 1.3e-3) * 1e9) * 1e-9
    assert runner.schedule._periods["/t"].last[False] == ev[8]       # the sample clock's arrival
    st.submit("/t", "commands", command, wall_5)
    assert st.outbox[-1][8] is None                                  # the twin's own time
    _, lock = _stepper(model)
    lock.submit("/t", "commands", command, wall_5 - 1.3e-3)
    assert lock.outbox[-1][0] == "cmd" and lock.outbox[-1][8] is None


def test_a_backlogs_newest_command_runs_the_steps_of_all_in_realtime(stewart, monkeypatch):
    """``submit(steps=0)``: a realtime twin applies and records a backlog's older command but
    runs no step for it; the newest runs the backlog's steps, as many as the wall clock allows
    (the last one answered). In lockstep every command owes one step whatever ``steps`` says."""
    import time

    model, program = stewart
    command = {"data": list(program.command_lengths(0.0))}
    runner, st = _stepper(model, mode="realtime")
    st._running = True
    st._t0 = time.perf_counter() - 1.0            # far behind the wall clock: steps run at once
    assert st.submit("/t", "commands", command, time.perf_counter(), steps=0) is None
    assert runner.schedule.accepted == 1 and runner.counters.steps == 0 and st._pending == 0
    assert st.outbox[-1][0] == "cmd"
    snap = st.submit("/t", "commands", command, time.perf_counter(), steps=3)
    assert runner.counters.steps == 3 and snap is not None and snap.answered and snap.state.t == runner.t
    import types

    import flexmb_io.realtime as R
    now = time.perf_counter()
    monkeypatch.setattr(R, "time", types.SimpleNamespace(perf_counter=lambda: now))   # the clock stands
    st._t0 = now - (st._n + 1.5 - st._command_lead) * runner.dt   # one more step allowed, then none
    snap = st.submit("/t", "commands", command, now, steps=3)
    assert runner.counters.steps == 4 and snap is not None and snap.answered
    runner, lock = _stepper(model)
    lock.submit("/t", "commands", command, 0.0, steps=0)
    assert lock._pending == 1


def test_a_command_finding_the_twin_at_its_lead_waits_for_the_next_step(stewart, monkeypatch):
    """Realtime: a command that finds the twin COMMAND_LEAD steps ahead of the wall clock is applied
    and recorded but runs no step and wakes no thread; the next command's step answers both, its
    latency counted from the older one's reception. (Stepping the waiting command at the first
    moment the lead allowed kept a 1 kHz stream at the lead for good: every command then waited.)"""
    import time
    import types

    import flexmb_io.realtime as R
    model, program = stewart
    command = {"data": list(program.command_lengths(0.0))}
    runner, st = _stepper(model, mode="realtime")
    st.cfg.publish_on_command = True
    st._running = True
    now = time.perf_counter()
    monkeypatch.setattr(R, "time", types.SimpleNamespace(perf_counter=lambda: now))   # the clock stands
    st._t0 = now - (st._n + 0.5 - st._command_lead) * runner.dt   # the step to n + 1 not allowed yet
    st.wake.clear()
    assert st.submit("/t", "commands", command, now - 2e-4) is None
    assert runner.counters.steps == 0 and runner.schedule.accepted == 1 and st.outbox[-1][0] == "cmd"
    assert not st.wake.is_set()                      # nothing steps it before the next step
    assert st.stats.commands_waited == 1
    st._t0 -= runner.dt                              # a period later: one step allowed
    snap = st.submit("/t", "commands", command, now)
    assert runner.counters.steps == 1 and snap is not None and snap.answered and snap.on_command
    assert snap.cmd_recv_wall == now - 2e-4          # the oldest command the state answers
    assert not st.wake.is_set()


def test_a_missed_deadline_is_told_apart_by_when_its_step_began(stewart, monkeypatch):
    """A miss whose step began after its deadline counts as started late (the thread came to it
    late); one that began in time and ended after it, as overran (``deadline_misses`` − started)."""
    import itertools
    import types

    import flexmb_io.realtime as R
    model, _ = stewart
    runner, st = _stepper(model, mode="realtime")
    ticks = itertools.count()                  # perf_counter: 0, 1, 2, … s, one per call
    monkeypatch.setattr(R, "time", types.SimpleNamespace(perf_counter=lambda: float(next(ticks))))
    st._step(-1.0)                             # began at 0 s, after its deadline
    assert (st.stats.deadline_misses, st.stats.misses_started_late) == (1, 1)
    start = next(ticks) + 1                    # the next step begins at this tick and ends after it
    st._step(start + 0.5)                      # began in time, ended late
    assert (st.stats.deadline_misses, st.stats.misses_started_late) == (2, 1)
    assert st.stats.misses_overran == 1
    st._step(math.inf)                         # unpaced (lockstep, ~/step): no deadline
    assert st.stats.deadline_misses == 2


def test_frames_prefix_the_platform_frames_only(stewart):
    from ros2_node.node import frame_prefix
    assert frame_prefix("auto", "/") == "" and frame_prefix("auto", "/robot1") == "robot1/"
    assert frame_prefix("auto", "/a/b") == "a/b/" and frame_prefix("", "/robot1") == ""
    assert frame_prefix("r2/", "/robot1") == "r2/"
    r = TwinRunner(stewart[0])
    s = r.start()
    frames = M.Frames(world="map", prefix="robot1/")
    tf = M.tf(s, frames)
    assert [t.child_frame_id for t in tf.transforms] == ["robot1/platform"]
    assert {t.header.frame_id for t in tf.transforms} == {"map"}
    assert M.platform_pose(s, 0, frames).header.frame_id == "map"
    assert M.joint_state(s).header.frame_id == "world"      # the default is unchanged


@pytest.mark.parametrize("margin", [4e-4, 2.5e-3])
def test_a_step_margin_beyond_dt_keeps_the_twin_ahead_and_commands_still_step_at_once(stewart, margin):
    """step_margin > Δt: the idle steps keep the twin ≈ margin ahead of the wall clock (a buffer
    against late wake-ups), and a command arriving then is still stepped on the receiving thread."""
    import time

    model, program = stewart
    runner = TwinRunner(model)
    runner.start()
    st = Stepper(runner, StepperConfig(mode="realtime", publish_every=10, margin=margin, rt_priority=0),
                 lambda: None)
    st.start()
    try:
        leads = []
        for _ in range(40):
            time.sleep(0.005)
            leads.append(runner.t - (time.perf_counter() - st._t0))
        snap = st.submit("/t", "commands", {"data": list(program.command_lengths(0.0))}, time.perf_counter())
    finally:
        st.stop()
    dt = runner.dt
    ahead = float(np.median(leads))
    if margin > dt:
        assert ahead > 0.5 * margin, (ahead, leads)     # the twin runs ahead of the clock by ≈ margin
    else:
        assert ahead < dt + 1e-4, (ahead, leads)        # at most the step in hand
    assert snap is not None and snap.answered           # the command's step ran at once, on this thread


def test_a_stalled_publisher_bounds_the_outbox_and_refuses_commands_it_could_not_record(stewart):
    """Nobody drains the outbox (the publisher stalled): it stops at ``outbox_limit`` events, the
    states beyond are counted as dropped publications, and a command is refused unapplied (it could
    not be recorded) and counted as ``publisher_stalled``; once drained, commands apply again."""
    from flexmb_io.commands import PUBLISHER_STALLED

    model, program = stewart
    runner = TwinRunner(model)
    runner.start()
    st = Stepper(runner, StepperConfig(mode="lockstep", publish_every=1, clock_every=1, outbox_limit=40),
                 lambda: None)
    st.hold()
    done, _ = st.step_n(100)
    assert done == 100 and len(st.outbox) == 40
    assert st.stats.stalled_drops == 2 * 100 + 2 - 40       # a state and a /clock per step, the held pair
    assert st.stats.dropped_publications == st.stats.stalled_drops
    command = {"data": list(program.command_lengths(0.0) + 0.001)}
    assert st.submit("/t", "commands", command, 0.0) is None
    assert runner.schedule.accepted == 0 and runner.counters.rejections == {PUBLISHER_STALLED: 1}
    assert len(st.outbox) == 40
    st.outbox.clear()
    st.submit("/t", "commands", command, 0.0)
    assert runner.schedule.accepted == 1 and st.outbox[-1][0] == "cmd"


def test_the_automatic_step_margin_covers_the_slow_steps_within_its_bounds(stewart):
    """``auto_margin``: the recent p99.9 step wall time plus the headroom, never under the configured
    margin, at most AUTO_MARGIN_STEPS Δt (unless the configured margin is larger); a Stepper starts
    at the widest and fits its margin, and the steps a command may lead with it, to its own step
    times."""
    from flexmb_io.realtime import AUTO_MARGIN_HEADROOM, AUTO_MARGIN_STEPS, COMMAND_LEAD, auto_margin

    dt = 1e-3
    assert auto_margin(0.3e-3, 0.4e-3, dt) == pytest.approx(0.3e-3 + AUTO_MARGIN_HEADROOM)
    assert auto_margin(0.05e-3, 0.4e-3, dt) == 0.4e-3                  # fast steps: the configured margin
    assert auto_margin(0.05, 0.4e-3, dt) == AUTO_MARGIN_STEPS * dt      # a pathological step: capped
    assert auto_margin(1e-3, 5e-3, dt) == 5e-3                          # a larger configured margin wins
    model, _ = stewart
    runner = TwinRunner(model)
    runner.start(warmup=False)
    st = Stepper(runner, StepperConfig(mode="realtime", margin=0.4e-3, margin_auto=True), lambda: None)
    # nothing measured yet: the widest margin of the rule (the first steps are the slowest)
    assert st.margin == AUTO_MARGIN_STEPS * dt and st._command_lead == COMMAND_LEAD + AUTO_MARGIN_STEPS
    st._update_margin()            # fewer than AUTO_MARGIN_EVERY steps: kept
    assert st.margin == AUTO_MARGIN_STEPS * dt
    fixed = Stepper(runner, StepperConfig(mode="realtime", margin=0.4e-3), lambda: None)
    assert fixed.margin == 0.4e-3 and fixed._command_lead == COMMAND_LEAD
    for k in range(1000):          # 1 % of the steps (tangent refreshes) take 0.9 ms, the others 0.1 ms
        st.step_walls.add(0.9e-3 if k % 100 == 0 else 0.1e-3)
    st._update_margin()
    assert st.margin == pytest.approx(0.9e-3 + AUTO_MARGIN_HEADROOM)
    assert st._command_lead == COMMAND_LEAD + 1
