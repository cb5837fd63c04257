"""Write a twin recording (ROS 2 MCAP, the live node's topics) from an offline simulation.

A test fixture until ``flexmb_io.bag.recorder`` lands: the same messages
(``flexmb_io.messages``) and schemas (``flexmb_io.wire``) the recorder uses, the scene as
the attachment ``scene.yaml`` and a ``flexmb`` metadata record. Log times are a wall-clock-like
epoch, unlike the header stamps (simulated time), so a reader that used log times would be caught.

    python tests/viz/twin_recording.py SCENE --until T --out OUT.mcap [--every S] [--bag]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from flexmb_core.model.compile import compile_scene
from flexmb_core.report import TwinReporter
from flexmb_core.scene import load_scene
from flexmb_core.simulator import Simulator
from flexmb_io import messages, topics
from flexmb_io import wire
from flexmb_io.shells import ShellShapes

LOG_EPOCH_NS = 1_700_000_000_000_000_000      # log times start here (s since 1970: 2023-11-14)


def write_recording(scene_path: str | Path, out: str | Path, *, until: float, every: float = 0.0,
                    attach_scene: bool = True, bag: bool = False, chunk_size: int = 1 << 20) -> dict:
    """Simulate ``scene_path`` to ``until`` and record a state every ``every`` s (0: every step)
    and at t = 0.

    ``bag=True`` writes a rosbag2 directory ``out`` (``metadata.yaml`` + ``out/<name>_0.mcap``);
    ``chunk_size`` (bytes) is the MCAP chunk size (small: many chunks, as a long recording has).
    Returns ``{"path", "times": [s, ...], "members", "actuators", "platforms", "counts",
    "shell_nodes"}``; ``shell_nodes[name] (N, 3)``: the shell's node positions at the last state,
    read straight from the state vector (m).
    """
    from mcap_ros2.writer import Writer

    scene_path = Path(scene_path)
    scene = load_scene(scene_path, {"until": until})
    model = compile_scene(scene)
    sim = Simulator(model)
    sim.warmup()
    sim.initialize()
    reporter = TwinReporter(model)
    shells = ShellShapes(model)
    kinds = tuple(m.kind for m in model.members)
    out = Path(out)
    mcap_path = out / f"{out.name}_0.mcap" if bag else out
    mcap_path.parent.mkdir(parents=True, exist_ok=True)

    types = {topics.JOINT_STATES.resolved(): topics.JOINT_STATES.type,
             topics.ACTUATOR_STATES.resolved(): topics.ACTUATOR_STATES.type,
             topics.SHAPE.resolved(): topics.SHAPE.type, topics.STATUS.resolved(): topics.STATUS.type,
             topics.TF.resolved(): topics.TF.type, topics.CLOCK.resolved(): topics.CLOCK.type,
             topics.COMMANDS.resolved(): topics.COMMANDS.type}
    poses = [o.name for o in scene.outputs if o.kind == "platform_pose"]
    for k, name in enumerate(poses):
        types[topics.pose_topic(name, k).resolved()] = topics.PLATFORM_POSE.type
    counts = dict.fromkeys(types, 0)
    times: list[float] = []

    with open(mcap_path, "wb") as stream:
        writer = Writer(stream, chunk_size=chunk_size)
        schemas = {}
        for typ in set(types.values()):
            schemas[typ] = writer.register_msgdef(typ, wire.schema(typ))
        seq = [0]

        def put(topic: str, msg: dict) -> None:
            log_ns = LOG_EPOCH_NS + 1_000_000 * seq[0] + 137      # not the stamp, on purpose
            writer.write_message(topic, schemas[types[topic]], wire.plain(msg), log_time=log_ns, publish_time=log_ns)
            counts[topic] += 1

        timing = messages.StatusTiming()
        since = [0.0, 0.0]                    # sim time and solver wall time at the last record (s)

        def record(step_wall: float) -> None:
            s = reporter.read(sim)
            shells.read(sim.state.q)
            timing.step_wall_time, timing.steps = step_wall, sim.stats.steps
            wall = sim.stats.wall_time_s
            if wall > since[1]:
                timing.real_time_factor = (s.t - since[0]) / (wall - since[1])
            since[:] = [s.t, wall]
            put(topics.CLOCK.resolved(), messages.clock(s.t))
            if s.actuator_names:
                # the command as the twin would have received it, just before this state
                put(topics.COMMANDS.resolved(), messages.float64_array(s.actuator_commands))
            put(topics.JOINT_STATES.resolved(), messages.joint_state(s))
            put(topics.ACTUATOR_STATES.resolved(), messages.actuator_state(s))
            for k, name in enumerate(poses):
                put(topics.pose_topic(name, k).resolved(), messages.platform_pose(s, k))
            if poses:
                put(topics.TF.resolved(), messages.tf(s))
            put(topics.SHAPE.resolved(), messages.shape(s, kinds, shells))
            put(topics.STATUS.resolved(), messages.status(s, timing))
            times.append(s.t)
            seq[0] += 1

        record(0.0)
        next_t = every
        while sim.state.t < until - 1e-12:
            t0 = time.perf_counter()
            sim.step(min(sim.spec.dt, until - sim.state.t))
            wall = time.perf_counter() - t0
            t = sim.state.t
            last = t >= until - 1e-12
            if every <= 0 or t >= next_t - 1e-9 or last:
                record(wall)
                next_t = (np.floor(t / every + 1e-6) + 1) * every if every > 0 else 0.0
        if attach_scene:
            now = time.time_ns()
            writer.add_attachment(create_time=now, log_time=now, name="scene.yaml",
                                          media_type="application/yaml", data=scene_path.read_bytes())
        writer.add_metadata("flexmb", {"scene": scene.name, "scene_file": str(scene_path),
                                               "dt": repr(scene.solver.dt), "until": repr(until)})
        writer.finish()

    if bag:
        _bag_metadata(out, mcap_path, types, counts, times)
    return {"path": out, "times": times, "members": [m.name for m in model.members],
            "actuators": list(model.actuators.names), "platforms": poses, "counts": counts,
            "shell_nodes": {sh.name: sim.state.q[sh.ydofs].copy() for sh in model.shells}}


def _bag_metadata(out: Path, mcap_path: Path, types: dict, counts: dict, times: list[float]) -> None:
    """A rosbag2 ``metadata.yaml`` (version 9) listing the file and its topics."""
    import yaml

    start = int(LOG_EPOCH_NS)
    duration = int(1_000_000 * max(len(times) - 1, 0)) + 1
    info = {"rosbag2_bagfile_information": {
        "version": 9, "storage_identifier": "mcap", "relative_file_paths": [mcap_path.name],
        "duration": {"nanoseconds": duration}, "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": sum(counts.values()),
        "topics_with_message_count": [
            {"topic_metadata": {"name": t, "type": typ, "serialization_format": "cdr",
                                "offered_qos_profiles": [], "type_description_hash": ""},
             "message_count": counts[t]} for t, typ in types.items()],
        "compression_format": "", "compression_mode": "",
        "files": [{"path": mcap_path.name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": sum(counts.values())}],
        "custom_data": {}, "ros_distro": "kilted"}}
    (out / "metadata.yaml").write_text(yaml.safe_dump(info, sort_keys=False))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--until", type=float, required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--every", type=float, default=0.0, help="record period (s); 0: every step")
    ap.add_argument("--bag", action="store_true", help="write a rosbag2 directory")
    args = ap.parse_args()
    info = write_recording(args.scene, args.out, until=args.until, every=args.every, bag=args.bag)
    print(f"{args.scene}: {len(info['times'])} states → {info['path']}")


if __name__ == "__main__":
    main()
