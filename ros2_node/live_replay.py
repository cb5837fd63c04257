"""``flexmb replay-live BAG``: replay a recording into a live twin node over DDS and compare the
node's new recording with the old one.

The offline replay (``flexmb replay``) checks the solver; this checks the whole live path: DDS,
the node's command handling, its stepping and its recorder. The node runs in lockstep (one step per
command), so the recording must have one command per step — a ``flexmb run --mcap`` recording or
a lockstep node's. Commands go out with KEEP_ALL history, and each waits for the status that
acknowledges it, so nothing is dropped however fast the replay runs (ROS_NOTES §4).

Outputs are matched by topic and header stamp and compared leaf by leaf (every number in the
message): positions and lengths to an absolute tolerance, every number to ``rel`` × the peak of its
field. Exit codes: 0 within tolerance, 3 beyond (or messages missing), 1 bad input.
"""

from __future__ import annotations

import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from flexmb_core.errors import FlexmbError
from flexmb_io import topics as T
from flexmb_io.bag.reader import obj_to_dict

_INPUT_SUFFIXES = {"commands": T.COMMANDS, "actuator_commands": T.ACTUATOR_COMMANDS,
                   "joint_trajectory": T.TRAJECTORY, "joint_commands": T.JOINT_COMMANDS}
_OUTPUTS = (T.JOINT_STATES, T.ACTUATOR_STATES, T.STATUS, T.TF)
# status fields that depend on the wall clock or on how often the node published
_VOLATILE = ("step_wall_time", "real_time_factor", "command_latency", "command_age", "deadline_misses", "steps",
             "command_stamp",
             "message", "rejected_commands")


def _leaves(d, prefix=""):
    if isinstance(d, dict):
        for k, v in d.items():
            if k in _VOLATILE or k == "header":
                continue
            yield from _leaves(v, f"{prefix}.{k}" if prefix else k)
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield from _leaves(v, f"{prefix}[{i}]")
    elif isinstance(d, bool) or not isinstance(d, (int, float)):
        yield prefix, d
    else:
        yield prefix, float(d)


def _stamp_ns(d) -> int | None:
    h = d.get("header") if isinstance(d, dict) else None
    if h is None and isinstance(d, dict) and d.get("transforms"):
        h = d["transforms"][0]["header"]
    if h is None:
        return None
    return h["stamp"]["sec"] * 1_000_000_000 + h["stamp"]["nanosec"]


def _outputs_by_stamp(reader, node_name: str) -> dict:
    """{topic: {stamp_ns: {leaf: value}}} of the comparable output topics."""
    names = {t.resolved(node_name) for t in _OUTPUTS} | {T.PLATFORM_POSE.resolved(node_name)}
    names |= {n for n in reader.topics() if n.endswith("platform_pose")}
    out: dict = defaultdict(dict)
    for m in reader.messages(names):
        d = obj_to_dict(m.decode())
        ns = _stamp_ns(d)
        if ns is not None:
            out[m.topic][ns] = dict(_leaves(d))
    return out


def compare_bags(old, new, node_name: str, *, abs_tol: float = 1e-9, rel_tol: float = 1e-9) -> tuple[bool, str]:
    """Compare the outputs two bags share, at the stamps they share. Returns (ok, report)."""
    a, b = _outputs_by_stamp(old, node_name), _outputs_by_stamp(new, node_name)
    lines, ok = [], True
    for topic in sorted(a):
        if topic not in b:
            lines.append(f"  {topic:32s} missing from the new recording")
            ok = False
            continue
        common = sorted(set(a[topic]) & set(b[topic]))
        if not common:
            lines.append(f"  {topic:32s} no common stamps")
            ok = False
            continue
        peaks: dict = defaultdict(float)
        for ns in common:
            for k, v in a[topic][ns].items():
                if isinstance(v, float):
                    peaks[k.split("[")[0]] = max(peaks[k.split("[")[0]], abs(v))
        worst, where = 0.0, ""
        for ns in common:
            va, vb = a[topic][ns], b[topic][ns]
            if va.keys() != vb.keys():
                lines.append(f"  {topic:32s} fields differ at t = {ns * 1e-9:.6f} s")
                ok = False
                break
            for k, x in va.items():
                y = vb[k]
                if isinstance(x, float) and isinstance(y, float):
                    dev = abs(x - y)
                    limit = max(abs_tol, rel_tol * peaks[k.split("[")[0]])
                    if not math.isfinite(y) or dev > limit:
                        ok = False
                    if dev / limit > worst:
                        worst, where = dev / limit, f"{k} = {y!r} vs {x!r} at t = {ns * 1e-9:.6f} s"
                elif x != y:
                    ok = False
                    worst, where = math.inf, f"{k}: {y!r} vs {x!r} at t = {ns * 1e-9:.6f} s"
        lines.append(f"  {topic:32s} {len(common):6d} stamps, worst deviation {worst:.3g} × tolerance"
                     + (f" ({where})" if worst > 0 else ""))
    return ok, "\n".join(lines)


def replay_live(bag: str, *, out: str, timeout: float = 30.0, abs_tol: float = 1e-9, rel_tol: float = 1e-9) -> int:
    from flexmb_io.bag.reader import BagReader

    old = BagReader(bag)
    scene_text = old.scene_text()
    if scene_text is None:
        raise FlexmbError(f"{bag}: no scene.yaml attachment; cannot rebuild the twin")
    node_name = old.setting("node_name", T.DEFAULT_NODE_NAME)
    if (old.setting("node_namespace") or "/") != "/":
        raise FlexmbError(f"{bag}: recorded in the namespace {old.setting('node_namespace')}; replay-live takes bags "
                          "of the root namespace (flexmb replay takes any)")
    dt = float(old.setting("dt"))
    integrator = old.setting("integrator")
    inputs = {t.resolved(node_name): t for t in _INPUT_SUFFIXES.values()}
    commands = [m for m in old.messages(set(inputs))]
    if not commands:
        raise FlexmbError(f"{bag}: no recorded commands on {sorted(inputs)}")
    times = [m.log_time_ns for m in commands]
    gaps = {round((b - a) * 1e-9 / dt, 6) for a, b in zip(times, times[1:])}
    if gaps - {1.0}:
        raise FlexmbError(f"{bag}: commands are not one per step (gaps of {sorted(gaps)[:5]} Δt): replay-live needs a "
                          "`flexmb run --mcap` or lockstep-node recording; use `flexmb replay` for others")
    publish_rate = float(old.setting("record_rate", 0) or 0) or 1.0 / dt

    tmp = Path(tempfile.mkdtemp(prefix="flexmb_replay_live_"))
    scene_file = tmp / "scene.yaml"
    scene_file.write_text(scene_text)
    env = dict(os.environ)                 # the discovery range cmd_replay_live configured (ros2_node.dds)
    env.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 200)))
    os.environ["ROS_DOMAIN_ID"] = env["ROS_DOMAIN_ID"]
    node_cmd = [sys.executable, "-m", "flexmb.cli", "node", str(scene_file), "--name", node_name, "--mode",
                "lockstep", "--dt", repr(dt), "--publish-rate", repr(publish_rate), "--shape-rate", "0",
                "--mcap", out, "--quiet"]
    if integrator:
        node_cmd += ["--integrator", integrator]
    # the recording's command hold (bags from before holds existed stepped: 'step')
    hold = (old.setting("runner_options", {}, as_json=True) or {}).get("command_hold", "step")
    node_cmd += ["--ros-args", "-p", f"command_hold:={hold}"]
    node = subprocess.Popen(node_cmd, env=env)
    try:
        _publish_all(commands, inputs, node_name, node, timeout)
    finally:
        if node.poll() is None:
            node.send_signal(signal.SIGINT)
            node.wait(timeout=60)
    if node.returncode not in (0, 130):      # 130: stopped by the SIGINT above, its normal end here
        raise FlexmbError(f"the twin node exited with {node.returncode}")
    ok, report = compare_bags(old, BagReader(out), node_name, abs_tol=abs_tol, rel_tol=rel_tol)
    print(f"replay-live of {bag}: {len(commands)} commands over DDS into a lockstep node; new recording {out}")
    print(report)
    print("result: " + ("the live node reproduces the recording (exit 0)" if ok else "beyond tolerance (exit 3)"))
    return 0 if ok else 3


def _publish_all(commands, inputs: dict, node_name: str, node, timeout: float) -> None:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from .convert import message_class

    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
    try:
        n = rclpy.create_node("flexmb_replay_live", context=ctx)
        keep_all = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
        pubs = {name: n.create_publisher(message_class(t.type), name, keep_all) for name, t in inputs.items()}
        steps = [-1]        # the newest status's step count; -1 until the twin is heard
        n.create_subscription(message_class(T.STATUS.type), T.STATUS.resolved(node_name),
                              lambda m: steps.__setitem__(0, max(steps[0], int(m.steps))), keep_all)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(n)
        t_end = time.monotonic() + 60.0
        while steps[0] < 0 or not all(p.get_subscription_count() for p in pubs.values()):
            if node.poll() is not None or time.monotonic() > t_end:
                raise FlexmbError("the twin node did not come up (no status, or it does not subscribe)")
            ex.spin_once(timeout_sec=0.05)
        for k, m in enumerate(commands, start=1):
            pubs[m.topic].publish(m.data)            # the recorded CDR bytes, as they were published
            t_end = time.monotonic() + timeout
            while steps[0] < k:
                if node.poll() is not None or time.monotonic() > t_end:
                    raise FlexmbError(f"no acknowledgement of command {k} (t = {m.t:.6f} s) within {timeout} s")
                ex.spin_once(timeout_sec=0.01)
        for p in pubs.values():
            p.wait_for_all_acked()
        ex.shutdown()
        n.destroy_node()
    finally:
        if ctx.ok():
            rclpy.shutdown(context=ctx)

