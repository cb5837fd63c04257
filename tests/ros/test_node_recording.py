"""Recordings of the live node: a lockstep node's bag replays offline bit-identically, an
offline run's bag replayed into a live node over DDS gives the same outputs (issue 6, part 4), and
a shell scene's ``~/shape`` (triangle lists) is the same live, recorded and in the node's .rrd."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("flexmb_msgs.msg")
pytest.importorskip("mcap_ros2")

from dds_harness import ROOT, NodeProcess, TwinClient  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402
from flexmb_io import messages as M  # noqa: E402
from flexmb_io import topics as T  # noqa: E402
from flexmb_io.bag.reader import BagReader  # noqa: E402
from ros2_node.convert import to_ros  # noqa: E402

pytestmark = pytest.mark.ros
FLEXMB = [sys.executable, "-m", "flexmb.cli"]


@pytest.mark.timeout(240)
def test_lockstep_node_recording_replays_bit_identically(tmp_path, dds_env):
    scene = "scenes/stewart_platform_bars.yaml"
    bag = tmp_path / "node_bag"
    node = NodeProcess([scene, "--mode", "lockstep", "--publish-rate", "200", "--mcap", str(bag)], dds_env,
                       tmp_path / "node.log")
    program = Simulator(compile_scene(load_scene(str(ROOT / scene))))
    client = TwinClient()
    try:
        client.wait_for_twin(node)
        for k in range(1, 201):
            before = max((int(s.steps) for s in client.statuses()), default=0)
            msg = to_ros(T.ACTUATOR_COMMANDS.type, M.actuator_command(k * 1e-3, program.model.actuators.names,
                                                                       program.command_lengths(k * 1e-3)))
            client.publish(T.ACTUATOR_COMMANDS, msg)
            client.spin_until(lambda: max((int(s.steps) for s in client.statuses()), default=0) > before, 30,
                              f"step {k}", node)
    finally:
        client.close()
        assert node.stop() == 130, node.log()     # SIGINT: the recorder closes the bag
    reader = BagReader(bag)
    counts = reader.counts()
    assert counts[T.ACTUATOR_COMMANDS.resolved()] == 200 and not reader.truncated
    assert counts[T.JOINT_STATES.resolved()] >= 200          # every step answers its command
    p = subprocess.run(FLEXMB + ["replay", str(bag)], cwd=ROOT, env=dds_env, capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "bit-identical" in p.stdout


@pytest.mark.timeout(240)
def test_run_bag_replayed_into_a_live_node_matches(tmp_path, dds_env):
    bag, new = tmp_path / "run_bag", tmp_path / "live_bag"
    p = subprocess.run(FLEXMB + ["run", "scenes/boom_step.yaml", "--until", "0.15", "--quiet", "--mcap", str(bag)],
                       cwd=ROOT, env=dds_env, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    p = subprocess.run(FLEXMB + ["replay-live", str(bag), "--out", str(new)], cwd=ROOT, env=dds_env,
                       capture_output=True, text=True, timeout=200)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "the live node reproduces the recording" in p.stdout
    # the comparison covered the outputs of the run (not an empty intersection)
    assert "/joint_states" in p.stdout and " 0 stamps" not in p.stdout


@pytest.mark.timeout(240)
def test_lockstep_node_publishes_records_and_logs_the_shells(tmp_path, dds_env):
    """The radiator panels (two shells) on a lockstep node with --mcap and --rrd: ``~/shape`` arrives
    over DDS with one TRIANGLE_LIST per shell, equal to the recorded one point for point; the bag
    replays bit-identically; the .rrd has a mesh per shell at every shape's stamp."""

    pytest.importorskip("rerun")
    scene = "scenes/radiator_panels.yaml"
    bag, rrd = tmp_path / "node_bag", tmp_path / "node.rrd"
    model = compile_scene(load_scene(str(ROOT / scene)))
    program = Simulator(model)
    dt = float(model.scene.solver.dt)
    node = NodeProcess([scene, "--mode", "lockstep", "--shape-rate", str(1.0 / dt), "--mcap", str(bag),
                        "--rrd", str(rrd)], dds_env, tmp_path / "node.log")
    client = TwinClient()
    steps = 10
    stamp = lambda m: m.markers[0].header.stamp.sec * 10**9 + m.markers[0].header.stamp.nanosec  # noqa: E731
    try:
        client.wait_for_twin(node)
        for k in range(1, steps + 1):
            before = max((int(s.steps) for s in client.statuses()), default=0)
            msg = to_ros(T.COMMANDS.type, M.float64_array(program.command_lengths(k * dt)))
            client.publish(T.COMMANDS, msg)
            client.spin_until(lambda: max((int(s.steps) for s in client.statuses()), default=0) > before, 30,
                              f"step {k}", node)
        t_end = round(steps * dt * 1e9)
        client.spin_until(lambda: any(stamp(m) == t_end for m in client.received[T.SHAPE.name]), 10,
                          "the last shape", node)
    finally:
        client.close()
        assert node.stop() == 130, node.log()
    members = [m.name for m in model.members]
    live = {stamp(m): m for m in client.received[T.SHAPE.name]}
    recorded = {stamp(m): m for m in (r.decode() for r in BagReader(bag).messages({T.SHAPE.resolved()}))}
    assert len(recorded) == steps + 1 and set(live) <= set(recorded) and t_end in live
    for ns, m in live.items():
        assert [mk.ns for mk in m.markers] == members + ["panel1", "panel2"]
        assert [mk.type for mk in m.markers[len(members):]] == [M.MARKER_TRIANGLE_LIST] * 2
        for a, b in zip(m.markers, recorded[ns].markers):
            assert a.type == b.type and a.id == b.id and len(a.points) == len(b.points)
            assert [(p.x, p.y, p.z) for p in a.points] == [(p.x, p.y, p.z) for p in b.points], (ns, a.ns)
        assert all(len(mk.points) == 4 * 9 * 3 for mk in m.markers[len(members):])
    p = subprocess.run(FLEXMB + ["replay", str(bag)], cwd=ROOT, env=dds_env, capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0 and "bit-identical" in p.stdout, p.stdout + p.stderr

    from rerun.chunk import RrdReader
    from flexmb_io.viz.layout import ShellLayout

    rows: dict[str, dict[int, np.ndarray]] = {}          # shell entity → sim_time (ns) → vertex positions
    for chunk in RrdReader(str(rrd)).stream():
        path = chunk.entity_path.strip("/")
        if path.startswith("world/shells/") and not chunk.is_static:
            rb = chunk.to_record_batch()
            for t, v in zip(rb.column("sim_time").cast("int64").to_pylist(),
                            rb.column("Mesh3D:vertex_positions").to_pylist()):
                rows.setdefault(path, {})[t] = np.array(v, dtype=np.float32)
    assert sorted(rows) == ["world/shells/panel1", "world/shells/panel2"]
    for k, info in enumerate(model.shells):
        logged = rows[f"world/shells/{info.name}"]
        assert set(logged) == set(recorded), info.name                # every shape the node recorded
        # the recorded triangle list, folded back onto the 28 mesh nodes, is what the node logged
        mk = recorded[t_end].markers[len(members) + k]
        nodes = np.array([[p.x, p.y, p.z] for p in mk.points])[ShellLayout.from_info(info).first]
        assert logged[t_end].shape == (28, 3) and np.array_equal(logged[t_end], nodes.astype(np.float32)), info.name
