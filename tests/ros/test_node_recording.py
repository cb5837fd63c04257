"""Recordings of the live node: a lockstep node's bag replays offline bit-identically, and an
offline run's bag replayed into a live node over DDS gives the same outputs (issue 6, part 4)."""

from __future__ import annotations

import subprocess
import sys

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("flexmb_msgs.msg")
pytest.importorskip("mcap_ros2")

from dds_harness import ROOT, NodeProcess, TwinClient  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402
from ros2_node import messages as M  # noqa: E402
from ros2_node import topics as T  # noqa: E402
from ros2_node.bag.reader import BagReader  # noqa: E402
from ros2_node.convert import to_ros  # noqa: E402

pytestmark = pytest.mark.ros
FLEXMB = [sys.executable, "-m", "ros2_node.cli"]


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
        assert node.stop() == 0, node.log()     # SIGINT: the recorder closes the bag
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
