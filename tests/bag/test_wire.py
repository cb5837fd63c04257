"""One message form, one serializer (:mod:`flexmb_io.wire`): rosbags' bytes equal an independent CDR
encoder's (mcap_ros2), decode back to the same values, and the schemas and RIHS01 hashes the bags
record equal the ones rosidl generated for the installed interfaces."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_io import messages as M
from flexmb_io import topics as T
from flexmb_io import wire
from flexmb_io.twin import TwinRunner

ROOT = Path(__file__).resolve().parents[2]
# every type the twin records (its inputs and outputs)
RECORDED_TYPES = tuple(dict.fromkeys(t.type for t in T.ALL if t is not T.DIAGNOSTICS))


def _sample_messages() -> dict:
    """One message per recorded type, with the awkward cases: empty arrays, non-ASCII strings,
    NumPy arrays, several markers and points, an odd number of bytes before 8-byte fields."""
    traj = {"header": M.header(0.25, "wörld"), "joint_names": ["a", "bb", "ccc"],
            "points": [{"positions": [1.0, 2.0, 3.0], "velocities": [], "accelerations": [], "effort": [],
                        "time_from_start": {"sec": 0, "nanosec": 5}},
                       {"positions": [1.5, 2.5, 3.5], "velocities": [0.1, 0.2, 0.3], "accelerations": [],
                        "effort": [], "time_from_start": {"sec": 1, "nanosec": 0}}]}
    marker = {"header": M.header(1.0), "ns": "legs/leg1", "id": 3, "type": 4, "action": 0,
              "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
              "scale": {"x": 0.05, "y": 0.0, "z": 0.0}, "color": {"r": 1.0, "g": 0.5, "b": 0.25, "a": 1.0},
              "points": [{"x": 0.1 * k, "y": -0.2 * k, "z": 1e-300 * k} for k in range(5)], "text": "é"}
    return {
        "std_msgs/msg/Float64MultiArray": M.float64_array(np.array([1.0, -2.5, np.pi])),
        "flexmb_msgs/msg/ActuatorCommand": M.actuator_command(0.1, ["legs/leg1", "b"], [1.05, 0.95]),
        "trajectory_msgs/msg/JointTrajectory": traj,
        "sensor_msgs/msg/JointState": {"header": M.header(3.000000001), "name": ["leg1", "knee"],
                                       "position": np.array([1.1, 0.2]), "velocity": [0.0, -1e-12],
                                       "effort": [1234.5, 0.0]},
        "flexmb_msgs/msg/ActuatorState": {"header": M.header(2.5), "names": ["x"], "lengths": [1.0],
                                          "velocities": [2.0], "commanded_lengths": [3.0], "axial_forces": [-4.0]},
        "geometry_msgs/msg/PoseStamped": {"header": M.header(0.001, "w"),
                                          "pose": {"position": {"x": 1.0, "y": 2.0, "z": 3.0},
                                                   "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}},
        "visualization_msgs/msg/MarkerArray": {"markers": [marker, dict(marker, ns="edge", id=4, points=[])]},
        "flexmb_msgs/msg/TwinStatus": {
            "header": M.header(0.5), "converged": True, "newton_iterations": 7, "residual": 1e-12,
            "kinetic_energy": 1.0, "strain_energy": 2.0, "total_energy": 3.0, "step_wall_time": 3e-5,
            "steps": 2 ** 40, "deadline_misses": 0, "unconverged_steps": 1, "real_time_factor": 20.5,
            "sim_time": 0.5, "substeps": 2, "message": "sub-steps: 2 — ok", "command_stamp": M.stamp(0.499),
            "command_latency": 0.0, "rejected_commands": 3, "command_age": 0.25},
        "rosgraph_msgs/msg/Clock": M.clock(12.345678901),
        "tf2_msgs/msg/TFMessage": {"transforms": [{"header": M.header(0.5), "child_frame_id": "platform",
                                                   "transform": {"translation": {"x": 1.0, "y": 0.0, "z": 0.5},
                                                                 "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}}]},
    }


def _jsonable(v):
    """NumPy arrays → lists (mcap_ros2's encoder takes plain sequences)."""
    return wire.plain(v)


def _installed(pkg: str, name: str, ext: str) -> Path | None:
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in prefixes + [Path(sys.prefix)]:
        p = prefix / "share" / pkg / "msg" / f"{name}.{ext}"
        if p.is_file():
            return p
    return None


def test_the_recorded_types_are_the_sampled_ones():
    assert set(RECORDED_TYPES) == set(_sample_messages()), RECORDED_TYPES


@pytest.mark.parametrize("type_name", RECORDED_TYPES)
def test_serialized_bytes_equal_mcap_ros2s_encoder(type_name):
    from mcap_ros2._dynamic import serialize_dynamic

    d = _sample_messages()[type_name]
    ours = wire.serialize(type_name, wire.make(type_name, d))
    theirs = serialize_dynamic(type_name, wire.schema(type_name))[type_name](_jsonable(d))
    assert ours == theirs, f"{type_name}: {len(ours)} vs {len(theirs)} bytes"
    assert ours[:4] == b"\x00\x01\x00\x00"          # CDR little endian encapsulation


@pytest.mark.parametrize("type_name", RECORDED_TYPES)
def test_what_is_serialized_decodes_to_the_same_values(type_name):
    from mcap_ros2.decoder import DecoderFactory
    from mcap.records import Schema

    d = _sample_messages()[type_name]
    msg = wire.make(type_name, d)
    data = wire.serialize(type_name, msg)
    assert wire.plain(wire.deserialize(type_name, data)) == wire.plain(msg)
    schema = Schema(id=1, name=type_name, encoding="ros2msg", data=wire.schema(type_name).encode())
    decoded = DecoderFactory().decoder_for("cdr", schema)(data)            # the reader's decoder
    if type_name == "sensor_msgs/msg/JointState":
        assert decoded.name == ["leg1", "knee"] and list(decoded.position) == [1.1, 0.2]
        assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (3, 1)
    elif type_name == "visualization_msgs/msg/MarkerArray":
        assert [m.ns for m in decoded.markers] == ["legs/leg1", "edge"]
        assert [p.z for p in decoded.markers[0].points][1] == 1e-300 and decoded.markers[0].text == "é"
    elif type_name == "flexmb_msgs/msg/TwinStatus":
        assert decoded.steps == 2 ** 40 and decoded.message == "sub-steps: 2 — ok" and decoded.substeps == 2
    elif type_name == "trajectory_msgs/msg/JointTrajectory":
        assert decoded.header.frame_id == "wörld" and list(decoded.points[1].velocities) == [0.1, 0.2, 0.3]


def test_missing_fields_take_zero_values():
    m = wire.make("flexmb_msgs/msg/ActuatorCommand")
    assert wire.plain(m) == {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}, "names": [],
                             "lengths": [], "velocities": []}
    assert wire.serialize("flexmb_msgs/msg/ActuatorCommand", m) == wire.serialize(
        "flexmb_msgs/msg/ActuatorCommand", M.actuator_command(0.0, [], []).__class__(
            header=M.header(0.0, ""), names=[], lengths=np.zeros(0), velocities=np.zeros(0)))


def test_an_unknown_type_is_named():
    with pytest.raises(KeyError, match="'no_msgs/msg/Nope'"):
        wire.schema("no_msgs/msg/Nope")


@pytest.mark.parametrize("scene", ["stewart_platform_bars.yaml", "stewart_platform_shell.yaml", "boom_step.yaml"])
def test_the_twins_messages_are_their_plain_values(scene):
    """Each builder's message serializes and decodes to the sample's numbers (nothing rounded)."""
    model = compile_scene(load_scene(ROOT / "scenes" / scene, {"until": 1.0}))
    runner = TwinRunner(model)
    s = runner.start()
    for _ in range(3):
        s = runner.step() or runner.sample()
    s = runner.sample()
    built = {T.JOINT_STATES.type: M.joint_state(s), T.ACTUATOR_STATES.type: M.actuator_state(s),
             T.SHAPE.type: M.shape(s, runner.member_kinds, runner.shells), T.CLOCK.type: M.clock(s.t),
             T.STATUS.type: M.status(s, M.StatusTiming(steps=3))}
    if s.poses:
        built[T.TF.type] = M.tf(s)
        built[T.PLATFORM_POSE.type] = M.platform_pose(s, 0)
    for type_name, msg in built.items():
        back = wire.deserialize(type_name, wire.serialize(type_name, msg))
        assert wire.plain(back) == wire.plain(msg), type_name
    js = built[T.JOINT_STATES.type]
    assert js.position[:len(s.actuator_lengths)].tolist() == s.actuator_lengths.tolist()
    assert js.effort[len(s.actuator_lengths):].tolist() == [0.0] * len(s.joint_names)


def test_type_hashes_equal_the_ones_rosidl_generated():
    checked = 0
    for t in RECORDED_TYPES:
        pkg, _, name = t.split("/")
        desc = _installed(pkg, name, "json")
        if desc is None:
            continue
        hashes = {h["type_name"]: h["hash_string"] for h in json.loads(desc.read_text())["type_hashes"]}
        assert wire.type_hash(t) == hashes[t], t
        checked += 1
    if _installed("std_msgs", "Header", "json") is None:
        pytest.skip("no installed type descriptions to compare with")
    assert checked >= 8, checked


def test_flexmb_msgs_come_from_the_package_data():
    """``flexmb_io/msg`` is the repository's ``msgs/msg`` (a link, shipped as files in a wheel)."""
    assert wire.flexmb_msgs_dir() == wire.PACKAGE_MSGS
    assert sorted(p.name for p in wire.PACKAGE_MSGS.glob("*.msg")) == sorted(
        p.name for p in (ROOT / "msgs" / "msg").glob("*.msg"))
    assert "MSG: std_msgs/Header" in wire.schema("flexmb_msgs/msg/TwinStatus")
