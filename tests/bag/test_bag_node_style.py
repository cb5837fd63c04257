"""A recording made the way the live node makes it — commands as received (named, stamped, and
trajectories) logged at the twin's time, outputs at a publish rate, the node's settings — replays
bit-identically, honouring the recorded runner options (command timeout and ramp to rest).
No rclpy: the node's stepping is TwinRunner's, its messages are flexmb_io.messages'."""

from __future__ import annotations

import numpy as np

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_io import messages as M
from flexmb_io import topics as T
from flexmb_io.bag.reader import BagReader, recover
from flexmb_io.bag.recorder import BagRecorder
from flexmb_io.bag.replay import replay
from flexmb_io.twin import RunnerOptions, TwinRunner, apply_message

from bag_helpers import ROOT, STEWART_BARS


def _record_like_the_node(out, options: RunnerOptions) -> dict:
    scene = load_scene(ROOT / STEWART_BARS)
    model = compile_scene(scene)
    runner = TwinRunner(model, options=options)
    runner.start()
    names = list(model.actuators.names)
    rest = model.actuators.l0.copy()
    n = "flexmb_twin"
    settings = {"dt": runner.dt, "integrator": runner.sim.spec.integrator, "mode": "lockstep", "node_name": n,
                "runner_options": vars(options), "source": "flexmb node"}
    rec = BagRecorder(out, scene_path=str(ROOT / STEWART_BARS), scene_text=(ROOT / STEWART_BARS).read_text(),
                      settings=settings)
    kinds = runner.member_kinds
    timing = M.StatusTiming()
    sent = {"actuator_commands": 0, "joint_trajectory": 0}

    def publish(s):
        t = s.t
        rec.write(T.JOINT_STATES.resolved(n), T.JOINT_STATES.type, M.joint_state(s), t)
        rec.write(T.ACTUATOR_STATES.resolved(n), T.ACTUATOR_STATES.type, M.actuator_state(s), t)
        rec.write(T.PLATFORM_POSE.resolved(n), T.PLATFORM_POSE.type, M.platform_pose(s), t)
        rec.write(T.STATUS.resolved(n), T.STATUS.type, M.status(s, timing), t)
        rec.write(T.SHAPE.resolved(n), T.SHAPE.type, M.shape(s, kinds), t)

    publish(runner.sample())
    for k in range(300):
        t = runner.t
        msg = None
        if k < 100 and k % 3 == 0:                  # named, stamped commands with rates, 333 Hz
            msg = ("actuator_commands", T.ACTUATOR_COMMANDS,
                   M.actuator_command(t, names[:3], rest[:3] + 0.002 * np.sin(30 * t), [0.06 * np.cos(30 * t)] * 3))
        elif k == 100:                              # one trajectory for the other legs
            pts = [{"positions": list(rest[3:] + d), "velocities": [], "accelerations": [], "effort": [],
                    "time_from_start": {"sec": 0, "nanosec": int(ns)}}
                   for d, ns in ((0.001, 2e7), (0.003, 6e7), (0.0, 9e7))]
            msg = ("joint_trajectory", T.TRAJECTORY,
                   {"header": M.header(t), "joint_names": names[3:], "points": pts})
        if msg is not None:                         # the node: record as received, then apply
            kind, topic, d = msg
            rec.write(topic.resolved(n), topic.type, d, runner.t)
            assert apply_message(runner, kind, topic.resolved(n), d) is None
            sent[kind] += 1
        out_ = runner.step()
        assert out_.advanced
        if k % 2 == 1 or k == 299:                  # publish at 500 Hz and the last state
            publish(runner.sample())
    rec.close()
    return sent


def test_node_style_recording_replays_exactly_with_its_runner_options(tmp_path):
    opts = RunnerOptions(command_timeout=0.05, timeout_behaviour="ramp_to_rest", ramp_time=0.05)
    sent = _record_like_the_node(tmp_path / "node", opts)
    assert sent == {"actuator_commands": 34, "joint_trajectory": 1}
    r = BagReader(tmp_path / "node")
    assert r.counts()[T.ACTUATOR_COMMANDS.resolved()] == 34
    rep = replay(tmp_path / "node")
    assert rep.ok, rep.format()
    assert rep.commands_applied == 35 and rep.commands_rejected == 0 and rep.steps == 300
    assert all(f.identical for f in rep.fields), rep.format()
    # the timeout mattered: after the commands stop, the legs ramp back to rest
    act = [m.decode() for m in r.messages({T.ACTUATOR_STATES.resolved()})]
    late, early = np.array(act[-1].commanded_lengths), np.array(act[40].commanded_lengths)
    rest = compile_scene(load_scene(ROOT / STEWART_BARS)).actuators.l0
    assert np.abs(early - late).max() > 1e-4 and np.abs(late[:3] - rest[:3]).max() < 1e-6


def test_replay_without_the_recorded_options_would_differ(tmp_path):
    """The same bag replayed with the default options (hold, 0.5 s) must fail: the options count."""
    import json

    from flexmb_io.bag.writer import BagWriter

    _record_like_the_node(tmp_path / "node", RunnerOptions(command_timeout=0.05, timeout_behaviour="ramp_to_rest",
                                                           ramp_time=0.05))
    src = BagReader(tmp_path / "node")
    out = BagWriter(tmp_path / "defaults")
    for a in src.attachment_records:
        out.add_attachment(a.name, bytes(a.data), a.media_type)
    meta = src.settings()
    meta["runner_options"] = json.dumps(vars(RunnerOptions()))
    out.add_metadata("flexmb", meta)
    chans = {cid: out.channel(ch.topic, src.schemas[ch.schema_id].name) for cid, ch in src.channels.items()}
    for m in src.messages_raw:
        out.write_cdr(chans[m.channel_id], bytes(m.data), m.log_time)
    out.close()
    rep = replay(tmp_path / "defaults")
    assert not rep.ok and rep.exit_code == 3
    assert any(f.field == "commanded_lengths" for f in rep.beyond())


def _record_bare_stream(out, with_arrivals: bool) -> list[float]:
    """A realtime node's recording of a 1 kHz bare stream: each command logged at the twin's time
    it was applied at (here 0–3 steps after it arrived, in order) with its wall-clock arrival as
    the publish time (``with_arrivals``; else none, as before arrivals were recorded). Returns the
    arrivals (s)."""
    scene = load_scene(ROOT / STEWART_BARS)
    model = compile_scene(scene)
    runner = TwinRunner(model, options=RunnerOptions())
    runner.start()
    rest = model.actuators.l0.copy()
    n = "flexmb_twin"
    settings = {"dt": runner.dt, "integrator": runner.sim.spec.integrator, "mode": "realtime", "node_name": n,
                "runner_options": vars(runner.options), "source": "flexmb node"}
    rec = BagRecorder(out, scene_path=str(ROOT / STEWART_BARS), scene_text=(ROOT / STEWART_BARS).read_text(),
                      settings=settings)
    rng = np.random.default_rng(4)
    sent = np.arange(240) * 1e-3 + 0.002
    arrival = np.round((sent + rng.uniform(0.0, 3e-4, sent.size)) * 1e9) * 1e-9
    applied = np.fmax.accumulate(np.ceil(arrival / 1e-3) * 1e-3 + rng.integers(0, 4, sent.size) * 1e-3)
    topic = T.COMMANDS.resolved(n)
    k = 0
    for step in range(250):
        while k < sent.size and applied[k] <= runner.t + 1e-12:
            d = {"data": list(rest + 0.02 * np.sin(8.0 * sent[k]) ** 2)}
            a = float(arrival[k]) if with_arrivals else None
            rec.write(topic, T.COMMANDS.type, d, runner.t, a)
            assert apply_message(runner, "commands", topic, d, a) is None
            k += 1
        assert runner.step().advanced
        s = runner.sample()
        rec.write(T.ACTUATOR_STATES.resolved(n), T.ACTUATOR_STATES.type, M.actuator_state(s), s.t)
    rec.close()
    return list(arrival)


def test_a_realtime_recordings_command_arrivals_replay_bit_for_bit(tmp_path):
    """A realtime node records a bare command's arrival (its DDS reception mapped onto the twin's
    time) as the message's publish time; ``flexmb replay`` applies it with it, bit for bit. The
    arrivals matter: the same commands replayed without them (publish time = log time) differ."""
    arrivals = _record_bare_stream(tmp_path / "rt", True)
    msgs = list(BagReader(tmp_path / "rt").messages({T.COMMANDS.resolved()}))
    assert [m.arrival for m in msgs] == [round(a * 1e9) * 1e-9 for a in arrivals]
    assert all(m.publish_time_ns != m.log_time_ns for m in msgs)
    recover(tmp_path / "rt", tmp_path / "copy")          # a bag rewritten keeps them
    assert [m.arrival for m in BagReader(tmp_path / "copy").messages({T.COMMANDS.resolved()})] == \
        [m.arrival for m in msgs]
    rep = replay(tmp_path / "rt")
    assert rep.ok and rep.fields and all(f.identical for f in rep.fields), rep.format()
    assert rep.commands_applied == len(arrivals)
    _record_bare_stream(tmp_path / "old", False)
    assert all(m.arrival is None for m in BagReader(tmp_path / "old").messages({T.COMMANDS.resolved()}))
    a = BagReader(tmp_path / "rt").messages({T.ACTUATOR_STATES.resolved()})
    b = BagReader(tmp_path / "old").messages({T.ACTUATOR_STATES.resolved()})
    assert any(x.data != y.data for x, y in zip(a, b))
