"""``tf2_msgs`` from ``ros/tf2_msgs`` (built into the venv by ``make setup``): the standard type, and ``/tf`` live.

- the generated type description's RIHS01 hash equals ROS 2's (rosbags' Humble and Jazzy stores)
  and that of the ``/tf`` schema the recorder writes (a shipped bag), so rviz, foxglove and rerun
  recognise the topic;
- the twin started from the venv (``flexmb node``) publishes ``/tf`` on DDS, announced with that
  type name and hash, one transform per platform frame.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("flexmb_msgs.msg")
pytest.importorskip("tf2_msgs.msg")

from twin_drive import drive_lockstep, standard_tfmessage_hash  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "stewart_platform_bars.yaml"
TYPE = "tf2_msgs/msg/TFMessage"


def _installed_hash(prefix: Path) -> str:
    """The RIHS01 hash rosidl generated for TFMessage under an install prefix."""
    description = json.loads((prefix / "share" / "tf2_msgs" / "msg" / "TFMessage.json").read_text())
    [own] = [h["hash_string"] for h in description["type_hashes"] if h["type_name"] == TYPE]
    return own


def _schema_hash(schema: str) -> str:
    """RIHS01 hash of TFMessage from a ros2msg schema text (the type, then '===' + 'MSG: pkg/Type' blocks)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    blocks = re.split(r"^=+\n", schema, flags=re.M)
    types = dict(get_types_from_msg(blocks[0], TYPE))
    for block in blocks[1:]:
        header, body = block.split("\n", 1)
        types.update(get_types_from_msg(body, header.removeprefix("MSG:").strip()))
    store.register(types)
    return store.hash_rihs01(TYPE)


def test_generated_type_is_ros2s_tfmessage():
    from rosbags.typesys import Stores, get_typestore

    import tf2_msgs

    prefix = Path(tf2_msgs.__file__).resolve().parents[4]          # <prefix>/lib/python3.x/site-packages/tf2_msgs
    standard = {get_typestore(s).hash_rihs01(TYPE) for s in (Stores.ROS2_HUMBLE, Stores.ROS2_JAZZY)}
    assert standard == {standard_tfmessage_hash()}
    assert _installed_hash(prefix) == standard_tfmessage_hash()
    assert (prefix / "share" / "tf2_msgs" / "flexmb_tfmessage_only").is_file()   # ours, not ROS 2's


def test_recorded_tf_schema_has_the_same_hash():
    from mcap.reader import make_reader

    bag = next((ROOT / "bags" / "stewart_bars_appendix").glob("*.mcap"))
    with open(bag, "rb") as f:
        schemas = {s.name: s.data.decode() for s in make_reader(f).get_summary().schemas.values()}
    assert _schema_hash(schemas[TYPE]) == standard_tfmessage_hash()


def test_venv_node_publishes_tf_live(tmp_path, dds_env):
    model = compile_scene(load_scene(str(SCENE)))
    log_path = tmp_path / "node.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "flexmb.cli", "node", str(SCENE), "--mode", "lockstep"],
                                env=dds_env, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
        try:
            out = drive_lockstep(model.actuators.l0, 30, dt=model.scene.solver.dt, alive=lambda: proc.poll() is None,
                                 log=log_path.read_text, timeout_up=240.0)
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=60)
    assert out.tf_publishers == [(TYPE, standard_tfmessage_hash())]
    frames = {(t.header.frame_id, t.child_frame_id) for m in out.tf for t in m.transforms}
    assert len(frames) == len(out.tf[0].transforms) >= 1, frames
    stamps = [m.transforms[0].header.stamp.sec + 1e-9 * m.transforms[0].header.stamp.nanosec for m in out.tf]
    # decimated to publish_rate (100 Hz of simulated time): stamps are steps of the run, in order
    assert stamps == sorted(stamps) and 0.0 < max(stamps) <= 30 * model.scene.solver.dt + 1e-12, stamps


def test_cmake_refuses_to_hide_ros2s_tf2_msgs(tmp_path):
    """With ROS 2's own tf2_msgs on AMENT_PREFIX_PATH, configuring ros/tf2_msgs stops and says what to do."""
    import os
    import shutil

    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed")
    underlay = tmp_path / "opt_ros"
    (underlay / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (underlay / "share" / "ament_index" / "resource_index" / "packages" / "tf2_msgs").touch()
    env = dict(os.environ, AMENT_PREFIX_PATH=f"{underlay}{os.pathsep}{sys.prefix}")
    proc = subprocess.run(["cmake", "-S", str(ROOT / "ros" / "tf2_msgs"), "-B", str(tmp_path / "build"), "-Wno-dev",
                           f"-DCMAKE_INSTALL_PREFIX={tmp_path / 'install'}"], env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode != 0
    message = " ".join(proc.stderr.split())
    assert f"ROS 2's own tf2_msgs is already installed in {underlay}" in message, proc.stderr[-2000:]
    assert "build with `colcon build --packages-skip tf2_msgs`" in message
