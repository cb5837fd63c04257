"""Fuzz (issue 15): 10⁴ mixed command messages — valid, malformed and hostile, seeded — on all four
command topics of a real-time twin node over DDS. The node
survives, answers SIGINT with 130 and its summary, counts the rejections by kind, logs no traceback
and never publishes a non-finite number.

The client paces itself (a short spin every 20 messages): what is measured is the node's handling.
An unpaced burst is the second test: what the node does not take is counted lost (README "Lost
commands")."""

from __future__ import annotations

import json
import math
import random
import time

import numpy as np
import pytest

from flexmb_io import topics as T

from dds_harness import NodeProcess, TwinClient

SCENE = "scenes/stewart_platform_bars.yaml"
MESSAGES = 10_000
NAMES = [f"leg{i}" for i in range(1, 7)]
REST = 1.0513


def _stamp(msg, t: float) -> None:
    ns = int(round(t * 1e9))
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9


def _value(rng: random.Random) -> float:
    """A length (m): mostly near the legs' rest, else something hostile."""
    return rng.choice([REST + rng.uniform(-1e-3, 1e-3)] * 6
                      + [math.nan, math.inf, -math.inf, 1e308, -5.0, 0.0, 3.0, 5e-324])


def _names(rng: random.Random) -> list[str]:
    pick = rng.random()
    if pick < 0.6:
        return list(NAMES)
    if pick < 0.75:
        return rng.sample(NAMES, rng.randint(1, 5))
    if pick < 0.85:
        return NAMES[:3] + ["no_such_leg"]
    if pick < 0.93:
        return ["leg1", "leg1"]
    return []


def _message(rng: random.Random, t_now: float):
    """One random (topic, message)."""
    from flexmb_msgs.msg import ActuatorCommand
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    kind = rng.randrange(4)
    if kind == 0:
        m = Float64MultiArray()
        m.data = [_value(rng) for _ in range(rng.choice([6, 6, 6, 0, 5, 7, 40]))]
        return T.COMMANDS, m
    if kind == 1:
        m = ActuatorCommand()
        m.names = _names(rng)
        m.lengths = [_value(rng) for _ in range(len(m.names) + rng.choice([0, 0, 0, 1, -1]) if m.names else 0)]
        m.velocities = rng.choice([[], [], [rng.choice([0.0, 0.01, math.nan, 1e308, -1e3])] * len(m.lengths)])
        _stamp(m, max(0.0, t_now + rng.choice([0.0, 0.0, 0.01, -0.5, 1e6, -1e6])))
        return T.ACTUATOR_COMMANDS, m
    if kind == 2:
        m = JointTrajectory()
        m.joint_names = _names(rng)
        n_pts = rng.choice([1, 2, 3, 0])
        for k in range(n_pts):
            p = JointTrajectoryPoint()
            p.positions = [_value(rng) for _ in range(rng.choice([len(m.joint_names)] * 4 + [0, 1]))]
            p.velocities = rng.choice([[], [rng.choice([0.0, math.nan, 1e308])] * len(p.positions)])
            t = rng.choice([0.01 * (k + 1), 0.01 * (k + 1), -0.5, 0.0, 1e6])
            p.time_from_start.sec = int(math.floor(t)) if abs(t) < 2**31 else 0
            p.time_from_start.nanosec = int((t - math.floor(t)) * 1e9) % 10**9 if abs(t) < 2**31 else 0
            m.points.append(p)
        _stamp(m, max(0.0, t_now + rng.choice([0.0, 0.0, 1e6])))
        return T.TRAJECTORY, m
    m = JointState()
    m.name = _names(rng)
    m.position = [_value(rng) for _ in range(len(m.name) + rng.choice([0, 0, 0, 1]) if m.name else 0)]
    m.velocity = rng.choice([[], [0.0] * len(m.position), [math.nan] * len(m.position)])
    m.effort = rng.choice([[], [], [1.0] * len(m.name)])
    return T.JOINT_COMMANDS, m


def _finite(msgs, fields) -> bool:
    return all(math.isfinite(v) for m in msgs for f in fields for v in getattr(m, f))


@pytest.mark.timeout(300)
def test_ten_thousand_mixed_messages_are_answered_and_nothing_breaks(tmp_path, dds_env):
    summary = tmp_path / "summary.json"
    node = NodeProcess([SCENE, "--mode", "realtime", "--duration", "120", "--summary-json", str(summary),
                        "--quiet"], dds_env, tmp_path / "node.log")
    client = TwinClient()
    rng = random.Random(20261124)
    try:
        client.wait_for_twin(node)
        for k in range(MESSAGES):
            st = client.statuses()
            topic, msg = _message(rng, st[-1].header.stamp.sec + 1e-9 * st[-1].header.stamp.nanosec if st else 0.0)
            client.publish(topic, msg)
            if k % 20 == 0:
                # paced at a few kHz: what is measured is the node's handling, not how much of an
                # unpaced burst DDS delivers (that depends on the machine's load)
                client.executor.spin_once(timeout_sec=0.002)
                assert node.alive(), node.log()[-3000:]
        steps_then = client.statuses()[-1].steps
        client.spin_until(lambda: client.statuses()[-1].steps > steps_then + 100, 30, "the twin to step on", node)
    finally:
        client.close()
        rc = node.stop()
    log = node.log_path.read_text()
    assert rc == 130, log[-3000:]
    assert "Traceback" not in log, log[-5000:]
    s = json.loads(summary.read_text())
    rejected = s["commands_rejected"]
    assert 50.0 < s["rss_mb"]["start"] <= s["rss_mb"]["max"], s["rss_mb"]     # the node's resident set, MB
    # every family of bad input was seen and counted by kind
    assert {"size", "not_finite", "unknown_name"} <= set(rejected), rejected
    assert sum(rejected.values()) > MESSAGES // 10, rejected
    assert s["failed_steps"] == 0 or s["failed_steps"] < s["steps"] // 100, s
    js, act = client.received[T.JOINT_STATES.name], client.received[T.ACTUATOR_STATES.name]
    assert js and act
    assert _finite(js, ("position", "velocity", "effort"))
    assert _finite(act, ("lengths", "velocities", "commanded_lengths", "axial_forces"))
    poses = client.received[T.PLATFORM_POSE.name]
    assert all(np.isfinite([m.pose.position.x, m.pose.position.y, m.pose.position.z]).all() for m in poses)


@pytest.mark.timeout(300)
def test_an_unpaced_burst_is_accounted_for_taken_or_counted_lost(tmp_path, dds_env):
    """10⁴ valid bare commands as fast as the client can publish them, into a subscription overridden
    to keep-all (README "Lost commands"): what the twin cannot take in time is lost upstream, and
    Fast DDS reports the gap (message_lost): the node counts it per topic in its summary and
    /diagnostics and warns. Only the burst's tail after the last delivered message can go unseen."""
    from rclpy.duration import Duration
    from std_msgs.msg import Float64MultiArray

    summary = tmp_path / "summary.json"
    node = NodeProcess([SCENE, "--mode", "realtime", "--duration", "120", "--summary-json", str(summary),
                        "--quiet", "--ros-args", "-p", "qos_overrides./flexmb_twin/commands.subscription.history:=keep_all"],
                       dds_env, tmp_path / "node.log")
    client = TwinClient()
    try:
        client.wait_for_twin(node)
        settled = time.monotonic() + 1.0       # the node's reader matches the client's writer too
        client.spin_until(lambda: time.monotonic() > settled, 5, "discovery to settle", node)
        for k in range(MESSAGES):
            client.publish(T.COMMANDS, Float64MultiArray(data=[REST + 1e-7 * (k % 100)] * 6))
        # first every sample still in the client's writer history is in the node's reader: one the
        # reader did not take (dropped on a loaded machine) is repeated only after the writer's next
        # heartbeat (Fast DDS: every 3 s), so the node's count could stand still for two reports
        # mid-burst (CI ended the test there once: 6662 taken + 1551 lost, the rest never delivered)
        assert client.pub[T.COMMANDS.name].wait_for_all_acked(Duration(seconds=120)), "the node never acknowledged the burst"
        # then the backlog is worked off when the node's count of accepted commands (/diagnostics,
        # once a second) stands still between two reports (the status rate alone is no sign: the node
        # applies a backlog in turns, several commands to one answer)
        last = [-1, 0]

        def drained() -> bool:
            reports = client.received[T.DIAGNOSTICS.name]
            if len(reports) == last[1]:
                return False
            values = {kv.key: kv.value for st in reports[-1].status for kv in st.values}
            accepted = int(values.get("accepted", -1))
            done = accepted == last[0] and accepted > 0
            last[:] = [accepted, len(reports)]
            return done
        client.spin_until(drained, 120, "the twin to work off the burst", node)
        settled = time.monotonic() + 1.5       # a /diagnostics after it
        client.spin_until(lambda: time.monotonic() > settled, 5, "a last /diagnostics", node)
        diagnostics = list(client.received[T.DIAGNOSTICS.name])
    finally:
        client.close()
        rc = node.stop()
    log = node.log_path.read_text()
    assert rc == 130, log[-3000:]
    s = json.loads(summary.read_text())
    taken = s["commands_accepted"] + sum(s["commands_rejected"].values())
    lost = sum(s["commands_lost"].values())
    assert taken + lost >= 0.9 * MESSAGES, (taken, lost, s["commands_lost"])
    assert taken + lost <= MESSAGES, (taken, lost)
    if lost:                          # a machine fast enough to take the whole burst loses nothing
        assert list(s["commands_lost"]) == ["/flexmb_twin/commands"], s["commands_lost"]
        assert "/flexmb_twin/commands: " in log and "commands lost before delivery so far" in log, log[-3000:]
        # the last /diagnostics came after the burst was worked off
        values = {kv.key: kv.value for st in diagnostics[-1].status for kv in st.values}
        assert 0 < int(values["lost_/flexmb_twin/commands"]) <= lost, values
