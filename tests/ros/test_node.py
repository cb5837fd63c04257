"""The twin node as a separate process on real DDS (loopback, random domain).

- lockstep: what the node publishes equals an offline TwinRunner run of the same commands (1e-12);
- every kind of bad command is rejected as documented, counted in status, and the node keeps going;
- joint trajectories are interpolated as the offline schedule does;
- realtime: /clock advances with the wall clock, status reports timing; bad parameters fail loudly.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("flexmb_msgs.msg")

from dds_harness import ROOT, NodeProcess, TwinClient  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402
from flexmb_io import messages as M  # noqa: E402
from flexmb_io import topics as T  # noqa: E402
from ros2_node.convert import to_ros  # noqa: E402
from flexmb_io.twin import TwinRunner, apply_message  # noqa: E402

pytestmark = pytest.mark.ros

SCENE = "scenes/stewart_platform_bars.yaml"
STEPS = 300


@pytest.fixture(scope="module")
def stewart():
    model = compile_scene(load_scene(str(ROOT / SCENE)))
    program = Simulator(model)          # only for the scene's command lengths L(t)
    return model, program


def _lockstep_node(tmp_path, dds_env, extra=()):
    return NodeProcess([SCENE, "--mode", "lockstep", "--publish-rate", "1000", "--shape-rate", "100", *extra],
                       dds_env, tmp_path / "node.log")


def _steps(client) -> int:
    return max((int(s.steps) for s in client.statuses()), default=0)


def _send_and_wait(client, node, topic, msg, timeout=30.0):
    """Publish and wait for the status of the step it caused (idle twins also send heartbeats)."""
    before = _steps(client)
    client.publish(topic, msg)
    client.spin_until(lambda: _steps(client) > before, timeout, f"the status answering {topic.name}", node)


@pytest.mark.timeout(180)
def test_lockstep_node_equals_offline_run(tmp_path, dds_env, stewart):
    model, program = stewart
    node = _lockstep_node(tmp_path, dds_env)
    client = TwinClient()
    try:
        client.wait_for_twin(node)
        offline = TwinRunner(model)
        offline.start()
        expected = {}
        for k in range(STEPS):
            t_next = offline.t + offline.dt
            lengths = program.command_lengths(t_next)
            _send_and_wait(client, node, T.COMMANDS, to_ros(T.COMMANDS.type, M.float64_array(lengths)))
            assert offline.command_array("/flexmb_twin/commands", lengths) is None
            offline.step()
            s = offline.sample()
            expected[round(s.t * 1e9)] = (s.actuator_lengths.copy(), s.actuator_velocities.copy(),
                                          s.actuator_forces.copy(), s.poses[0].position.copy(),
                                          s.poses[0].orientation_wxyz.copy())
        t_end = round(offline.t * 1e9)
        stamp = lambda m: m.header.stamp.sec * 10**9 + m.header.stamp.nanosec  # noqa: E731
        client.spin_until(lambda: any(stamp(m) == t_end for m in client.received[T.JOINT_STATES.name])
                          and any(stamp(m) == t_end for m in client.received[T.PLATFORM_POSE.name]),
                          10, "the last states", node)
    finally:
        client.close()
        rc = node.stop()
    assert rc == 130, node.log()        # stopped by SIGINT: the README's exit code

    js = [m for m in client.received[T.JOINT_STATES.name] if m.header.stamp.sec or m.header.stamp.nanosec]
    poses = [m for m in client.received[T.PLATFORM_POSE.name] if m.header.stamp.sec or m.header.stamp.nanosec]
    assert len(js) >= STEPS and len(poses) >= STEPS
    worst = 0.0
    for m in js:
        key = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
        lengths, rates, forces, _, _ = expected[key]
        assert list(m.name) == list(model.actuators.names)
        worst = max(worst, np.abs(np.array(m.position) - lengths).max(), np.abs(np.array(m.velocity) - rates).max(),
                    np.abs(np.array(m.effort) - forces).max() / max(1.0, np.abs(forces).max()))
    for m in poses:
        key = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
        *_, pos, quat = expected[key]
        p, o = m.pose.position, m.pose.orientation
        worst = max(worst, np.abs(np.array([p.x, p.y, p.z]) - pos).max(),
                    np.abs(np.array([o.w, o.x, o.y, o.z]) - quat).max())
    assert worst <= 1e-12, f"live lockstep node vs offline run: worst deviation {worst:.3e}"
    last = client.statuses()[-1]
    assert last.converged and last.steps == STEPS and last.rejected_commands == 0
    shapes = client.received[T.SHAPE.name]
    assert shapes and len(shapes[-1].markers) == len(model.members)
    assert all(math.isfinite(pt.z) for mk in shapes[-1].markers for pt in mk.points)


def _named(names, lengths, t=0.0, velocities=None):
    return to_ros(T.ACTUATOR_COMMANDS.type, M.actuator_command(t, names, lengths, velocities))


@pytest.mark.timeout(180)
def test_bad_commands_are_rejected_and_the_node_keeps_stepping(tmp_path, dds_env, stewart):
    model, program = stewart
    names = list(model.actuators.names)
    node = _lockstep_node(tmp_path, dds_env)
    client = TwinClient()
    good = program.command_lengths(0.0)
    cases = [
        ("size", T.COMMANDS, to_ros(T.COMMANDS.type, M.float64_array(good[:4]))),
        ("not_finite", T.COMMANDS, to_ros(T.COMMANDS.type, M.float64_array([math.nan] + list(good[1:])))),
        ("not_finite", T.COMMANDS, to_ros(T.COMMANDS.type, M.float64_array([math.inf] + list(good[1:])))),
        ("stroke", T.COMMANDS, to_ros(T.COMMANDS.type, M.float64_array([2.5] + list(good[1:])))),
        ("unknown_name", T.ACTUATOR_COMMANDS, _named(["leg1", "no_such_leg"], good[:2])),
        ("future", T.ACTUATOR_COMMANDS, _named(names, good, t=1.0e9)),
    ]
    try:
        client.wait_for_twin(node)
        # a valid stamped command first, at t = 0.5 s ahead, so that older stamps are out of order
        _send_and_wait(client, node, T.ACTUATOR_COMMANDS, _named(names, good, t=0.5))
        cases.append(("out_of_order", T.ACTUATOR_COMMANDS, _named(names, good, t=0.25)))
        for k, (kind, topic, msg) in enumerate(cases):
            _send_and_wait(client, node, topic, msg)
            st = client.statuses()[-1]
            assert st.rejected_commands == k + 1, f"case {kind}: status says {st.rejected_commands} rejected"
        # still alive and stepping on the last valid command; never NaN
        _send_and_wait(client, node, T.COMMANDS, to_ros(T.COMMANDS.type, M.float64_array(good)))
        assert node.alive()
    finally:
        client.close()
        rc = node.stop()
    assert rc == 130
    log = node.log_path.read_text()     # complete once the node stopped (its log is written apart)
    for kind, topic, _ in cases:
        assert f"{topic.resolved()}: rejected ({kind})" in log, f"no log line for {kind}:\n{log}"
    assert "stroke [0.65, 1.65] m" in log and "no_such_leg" in log
    st = client.statuses()[-1]
    assert st.steps == len(cases) + 2 and st.converged
    for m in client.received[T.JOINT_STATES.name]:
        assert all(math.isfinite(v) for v in (*m.position, *m.velocity, *m.effort))


@pytest.mark.timeout(180)
def test_joint_trajectory_is_interpolated_like_offline(tmp_path, dds_env, stewart):
    model, program = stewart
    names = list(model.actuators.names)
    l0 = program.command_lengths(0.0)
    traj = {"header": M.header(0.0), "joint_names": names,
            "points": [{"positions": (l0 + 0.01).tolist(), "velocities": [0.0] * 6, "accelerations": [],
                        "effort": [], "time_from_start": {"sec": 0, "nanosec": 100_000_000}},
                       {"positions": (l0 - 0.005).tolist(), "velocities": [0.0] * 6, "accelerations": [],
                        "effort": [], "time_from_start": {"sec": 0, "nanosec": 200_000_000}}]}
    node = _lockstep_node(tmp_path, dds_env)
    client = TwinClient()
    offline = TwinRunner(model)
    offline.start()
    try:
        client.wait_for_twin(node)
        _send_and_wait(client, node, T.TRAJECTORY, to_ros(T.TRAJECTORY.type, traj))
        assert apply_message(offline, "joint_trajectory", "/flexmb_twin/joint_trajectory", traj) is None
        offline.step()
        # lockstep steps once per command message, and a rejected one leaves the trajectory in force
        bad = to_ros(T.COMMANDS.type, M.float64_array([1.0]))          # size error → rejected, one step
        for _ in range(249):
            _send_and_wait(client, node, T.COMMANDS, bad)
            apply_message(offline, "commands", "/flexmb_twin/commands", {"data": [1.0]})
            offline.step()
        t_end = round(offline.t * 1e9)
        client.spin_until(lambda: any(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == t_end
                                      for m in client.received[T.ACTUATOR_STATES.name]), 10, "the last state", node)
    finally:
        client.close()
        node.stop()
    s = offline.sample()
    last = [m for m in client.received[T.ACTUATOR_STATES.name]][-1]
    assert abs(last.header.stamp.sec + 1e-9 * last.header.stamp.nanosec - s.t) < 1e-9
    assert np.abs(np.array(last.commanded_lengths) - s.actuator_commands).max() <= 1e-12
    # at t = 0.25 s the trajectory has ended: its last point is held
    assert np.abs(s.actuator_commands - (l0 - 0.005)).max() <= 1e-12
    assert np.abs(np.array(last.lengths) - s.actuator_lengths).max() <= 1e-12


@pytest.mark.timeout(120)
def test_realtime_node_owns_the_clock(tmp_path, dds_env):
    node = NodeProcess([SCENE, "--mode", "realtime", "--duration", "4", "--publish-rate", "200",
                        "--summary-json", str(tmp_path / "s.json"), "--quiet"], dds_env, tmp_path / "node.log")
    client = TwinClient()
    try:
        client.wait_for_twin(node)
        client.spin_until(lambda: len(client.received[T.CLOCK.name]) > 100, 30, "/clock", node)
    finally:
        client.close()
    node.proc.wait(timeout=60)
    assert node.stop() == 0, node.log()
    clocks = [m.clock.sec + 1e-9 * m.clock.nanosec for m in client.received[T.CLOCK.name]]
    assert all(b > a for a, b in zip(clocks, clocks[1:]))
    import json
    s = json.loads((tmp_path / "s.json").read_text())
    assert abs(s["sim_time_s"] - 4.0) < 1e-6 and s["steps"] == 4000
    assert 0.5 < s["rtf"] < 1.05            # paced by the wall clock (never faster than real time)
    st = client.statuses()[-1]
    assert st.real_time_factor > 0 and st.converged


def test_the_cli_parameter_names_of_this_node():
    from ros2_node.node import cli_param_names

    args = ["-r", "__ns:=/r1", "-p", "dt:=0.002", "--param", "flexmb_twin:mode:=lockstep", "-p", "other:x:=1",
            "--params-file", "/tmp/p.yaml", "-p", "bad_item"]
    assert cli_param_names(args, "flexmb_twin") == ("dt", "mode")
    assert cli_param_names(None, "flexmb_twin") == ()


@pytest.mark.parametrize("args, expected", [
    (["--ros-args", "-p", "publish_rate:=-5.0"], "parameter 'publish_rate' (flag --publish-rate or -p publish_rate:=...): "
                                                 "expected a value in [1, 10000]"),
    (["--clock-rate", "0"], "parameter 'clock_rate' (flag --clock-rate or -p clock_rate:=...): expected a value in [1, "),
    (["--ros-args", "-p", "dt:=abc"], "parameter 'dt' (flag --dt or -p dt:=...): expected a float; rclpy: "),
    (["--cpu-affinity", "0,4096"], "parameter 'cpu_affinity': CPU 4096 is not one this process may run on (allowed: ["),
    (["--ros-args", "-p", "publish_rte:=50.0"], "parameter 'publish_rte' (-p publish_rte:=...): no parameter of the "
                                                "twin node has this name; did you mean 'publish_rate'"),
    (["--ros-args", "-p", "flexmb_twin:publish_rte:=50.0"], "parameter 'publish_rte' (-p publish_rte:=...): "),
])
def test_bad_parameter_fails_with_a_clear_message(dds_env, args, expected):
    p = subprocess.run([sys.executable, "-m", "flexmb.cli", "node", SCENE] + args,
                       env=dds_env, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 1
    assert expected in p.stderr
    assert "Traceback" not in p.stderr + p.stdout
