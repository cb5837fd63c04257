"""The recorder's CDR encoder: byte-identical to mcap_ros2's, decodable by rosbags, strict on bad values."""

from __future__ import annotations

import numpy as np
import pytest

from flexmb_io import messages as M
from flexmb_io.bag.cdr import CdrError, compile_encoder
from flexmb_io.bag.schemas import RECORDED_TYPES, schema_text


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


def _to_jsonable(msg: dict) -> dict:
    """NumPy arrays → lists (mcap_ros2's encoder takes plain sequences)."""
    if isinstance(msg, dict):
        return {k: _to_jsonable(v) for k, v in msg.items()}
    if isinstance(msg, (list, tuple)):
        return [_to_jsonable(v) for v in msg]
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    return msg


@pytest.mark.parametrize("type_name", RECORDED_TYPES)
def test_encoder_is_byte_identical_to_mcap_ros2(type_name):
    from mcap_ros2._dynamic import serialize_dynamic

    msg = _sample_messages()[type_name]
    ours = compile_encoder(type_name)(msg)
    theirs = serialize_dynamic(type_name, schema_text(type_name))[type_name](_to_jsonable(msg))
    assert ours == theirs, f"{type_name}: {len(ours)} vs {len(theirs)} bytes"
    assert ours[:4] == b"\x00\x01\x00\x00"          # CDR little endian encapsulation


@pytest.mark.parametrize("type_name", RECORDED_TYPES)
def test_rosbags_decodes_what_we_encode(type_name):
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(schema_text(type_name), type_name))
    msg = _sample_messages()[type_name]
    decoded = store.deserialize_cdr(compile_encoder(type_name)(msg), type_name)
    if type_name == "sensor_msgs/msg/JointState":
        assert decoded.name == ["leg1", "knee"]
        assert decoded.position.tolist() == [1.1, 0.2] and decoded.effort.tolist() == [1234.5, 0.0]
        assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (3, 1)
    elif type_name == "visualization_msgs/msg/MarkerArray":
        assert [m.ns for m in decoded.markers] == ["legs/leg1", "edge"]
        assert [p.z for p in decoded.markers[0].points][1] == 1e-300 and decoded.markers[0].text == "é"
        assert decoded.markers[1].points == []
    elif type_name == "flexmb_msgs/msg/TwinStatus":
        assert decoded.steps == 2 ** 40 and decoded.message == "sub-steps: 2 — ok" and decoded.substeps == 2
    elif type_name == "trajectory_msgs/msg/JointTrajectory":
        assert decoded.header.frame_id == "wörld" and decoded.points[1].velocities.tolist() == [0.1, 0.2, 0.3]
        assert decoded.points[0].velocities.size == 0


def test_missing_keys_take_zero_values():
    enc = compile_encoder("flexmb_msgs/msg/ActuatorCommand")
    full = M.actuator_command(0.0, [], [])
    full["header"]["frame_id"] = ""
    assert enc({}) == enc(full)


def test_bad_values_are_rejected_with_the_type_name():
    enc = compile_encoder("sensor_msgs/msg/JointState")
    with pytest.raises(CdrError, match="sensor_msgs/msg/JointState"):
        enc({"position": ["not a number"]})
    with pytest.raises(CdrError, match="JointState"):
        enc({"header": {"stamp": {"sec": 2 ** 40, "nanosec": 0}}})          # int32 overflow


def test_every_field_form_matches_mcap_ros2():
    """Fixed and bounded arrays, bools, bytes, int widths, constants and defaults — forms the
    recorded types do not use yet — against mcap_ros2's serializer."""
    from mcap_ros2._dynamic import serialize_dynamic

    schema = "\n".join([
        "int32 CONSTANT=7", "string NAME = 'x'",
        "bool flag", "uint8[] raw", "bool[3] bits", "int8 small", "float64[4] quad", "int16 mid",
        "float32[<=5] bounded", "string<=8 short", "string[2] pair", "uint64 big", "Inner[] inners", "Inner one",
        "Inner[2] two", "float64 with_default 1.5",
        "=" * 80, "MSG: test_pkg/Inner", "byte b", "float64 x", "int64[] ys"])
    msg = {"flag": True, "raw": [1, 2, 255], "bits": [True, False, True], "small": -3, "quad": [1.0, 2.0, 3.0, 4.0],
           "mid": -300, "bounded": [0.5, 0.25], "short": "abc", "pair": ["p", "qq"], "big": 2 ** 63,
           "inners": [{"b": 9, "x": 0.1, "ys": [1, -2]}], "one": {"b": 1, "x": -1.0, "ys": []},
           "two": [{"b": 2, "x": 2.0, "ys": [3]}, {"b": 3, "x": 3.0, "ys": []}], "with_default": 2.5}
    ours = compile_encoder("test_pkg/msg/Outer", schema)(msg)
    theirs = serialize_dynamic("test_pkg/Outer", schema)["test_pkg/Outer"](msg)
    assert ours == theirs
    assert compile_encoder("test_pkg/msg/Outer", schema)(dict(msg, raw=bytes([1, 2, 255]))) == theirs
    with pytest.raises(CdrError, match="expected 4"):
        compile_encoder("test_pkg/msg/Outer", schema)(dict(msg, quad=[1.0]))
    with pytest.raises(CdrError, match="wstring"):
        compile_encoder("test_pkg/msg/W", "wstring w\n")
