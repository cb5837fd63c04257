"""BagRecorder: the rosbag2 layout, the self-describing MCAP records, chunking, errors; and the
reader's tolerance to files cut at any byte (what a SIGKILL leaves)."""

from __future__ import annotations

import hashlib
import struct

import pytest
import yaml

from flexmb_io import messages as M
from flexmb_io.bag.reader import MAGIC, BagReader, recover
from flexmb_io.bag.recorder import BagRecorder
from flexmb_io.bag.writer import BagError

from bag_helpers import ROOT

SCENE = ROOT / "scenes" / "actuator_arm.yaml"
JS = "sensor_msgs/msg/JointState"
ST = "flexmb_msgs/msg/TwinStatus"


def _joint_state(t: float) -> dict:
    return {"header": M.header(t), "name": ["lift"], "position": [1.0 + t], "velocity": [t], "effort": [-t]}


def _status(t: float) -> dict:
    return {"header": M.header(t), "converged": True, "newton_iterations": 3, "sim_time": t, "message": ""}


def _record(out, n: int = 1000, dt: float = 1e-3, **kw) -> BagRecorder:
    rec = BagRecorder(out, scene_path=str(SCENE), scene_text=SCENE.read_text(), settings={"dt": dt, "x": {"a": 1}},
                      **kw)
    for k in range(n):
        t = k * dt
        rec.write("/joint_states", JS, _joint_state(t), t)
        if k % 10 == 0:
            rec.write("/flexmb_twin/status", ST, _status(t), t)
    return rec


def test_layout_metadata_yaml_and_self_description(tmp_path):
    out = tmp_path / "bag"
    with _record(out) as rec:
        assert (out / "metadata.yaml").is_file()                  # provisional file exists while recording
    rec.close()                                                   # idempotent
    assert sorted(p.name for p in out.iterdir()) == ["bag_0.mcap", "metadata.yaml"]
    info = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["bag_0.mcap"] and info["files"][0]["path"] == "bag_0.mcap"
    assert info["message_count"] == 1100 and info["files"][0]["message_count"] == 1100
    assert info["starting_time"]["nanoseconds_since_epoch"] == 0
    assert info["duration"]["nanoseconds"] == 999_000_000            # simulated time, ns
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert topics["/joint_states"]["message_count"] == 1000
    assert topics["/flexmb_twin/status"]["topic_metadata"]["type"] == ST
    md = topics["/flexmb_twin/status"]["topic_metadata"]
    assert md["serialization_format"] == "cdr" and md["type_description_hash"].startswith("RIHS01_")
    assert md["offered_qos_profiles"][0]["reliability"] == "reliable"
    assert md["offered_qos_profiles"][0]["history"] == "keep_last" and md["offered_qos_profiles"][0]["depth"] == 10

    r = BagReader(out)
    assert not r.truncated and r.profile == "ros2"
    assert r.scene_text() == SCENE.read_text()
    s = r.settings()
    assert s["scene"] == "actuator_arm" and s["scene_file"] == str(SCENE)
    assert s["scene_sha256"] == hashlib.sha256(SCENE.read_bytes()).hexdigest()
    assert s["dt"] == "0.001" and s["x"] == '{"a": 1}' and s["node_name"] == "flexmb_twin" and s["version"]
    assert all(sch.encoding == "ros2msg" for sch in r.schemas.values())
    assert "MSG: std_msgs/Header" in bytes(next(sch for sch in r.schemas.values() if sch.name == ST).data).decode()
    # log time = publish time = simulated time
    msgs = list(r.messages({"/joint_states"}))
    assert [m.log_time_ns for m in msgs[:3]] == [0, 1_000_000, 2_000_000]
    assert all(m.log_time == m.publish_time for m in r.messages_raw)
    assert msgs[500].decode().position[0] == pytest.approx(1.5)
    # chunks: one per 0.25 s of simulated time, zstd
    assert r.chunks == 4


def test_summary_readable_by_the_mcap_library(tmp_path):
    from mcap.reader import make_reader

    _record(tmp_path / "b").close()
    with open(tmp_path / "b" / "b_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == 1100 and summary.statistics.chunk_count == 4
    assert {ci.compression for ci in summary.chunk_indexes} == {"zstd"}
    assert {ch.metadata["offered_qos_profiles"].startswith("- history: keep_last")
            for ch in summary.channels.values()} == {True}


def test_refuses_to_overwrite_and_bad_arguments(tmp_path):
    out = tmp_path / "b"
    _record(out, n=3).close()
    with pytest.raises(BagError, match="already exists and is not an empty directory"):
        BagRecorder(out, scene_path=str(SCENE), scene_text=None, settings={})
    with pytest.raises(BagError, match="pass the file's content, not its path"):
        BagRecorder(tmp_path / "c", scene_path="other.yaml", scene_text=str(SCENE), settings={})
    with BagRecorder(tmp_path / "c2", scene_path=str(SCENE), scene_text=str(SCENE), settings={}) as rec:
        pass                                              # the path itself (Scene.source): the file is read
    assert BagReader(tmp_path / "c2").scene_text() == SCENE.read_text()
    with pytest.raises(BagError, match="chunk_seconds must be > 0"):
        BagRecorder(tmp_path / "d", scene_path=str(SCENE), scene_text=None, settings={}, chunk_seconds=0)
    rec = BagRecorder(tmp_path / "e", scene_path=str(SCENE), scene_text=None, settings={})
    with pytest.raises(BagError, match="finite and ≥ 0"):
        rec.write("/joint_states", JS, _joint_state(0.0), -1e-3)
    rec.write("/joint_states", JS, _joint_state(0.0), 0.0)
    with pytest.raises(BagError, match="recorded as sensor_msgs/msg/JointState"):
        rec.write("/joint_states", ST, _status(0.0), 0.0)
    rec.close()
    with pytest.raises(BagError, match="closed"):
        rec.write("/joint_states", JS, _joint_state(0.0), 0.0)


def _layout(data: bytes) -> tuple[int, list[tuple[int, int]]]:
    """End offset of the ``flexmb`` metadata record, and (end offset, messages so far) after every
    chunk (its message indexes follow it and are not needed to read it)."""
    import io

    from mcap.data_stream import ReadDataStream
    from mcap.opcode import Opcode
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk

    pos, out, count, meta_end = 8, [], 0, None
    while pos < len(data):
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        end = pos + 9 + length
        if op == Opcode.METADATA:
            meta_end = end
        elif op == Opcode.CHUNK:
            ch = Chunk.read(ReadDataStream(io.BytesIO(data[pos + 9:end])))
            count += sum(isinstance(r, Message) for r in breakup_chunk(ch))
            out.append((end, count))
        elif op == Opcode.DATA_END:
            break
        pos = end
    return meta_end, out


def test_a_file_cut_at_any_byte_keeps_exactly_its_complete_chunks(tmp_path):
    _record(tmp_path / "full", n=2000, chunk_messages=300).close()
    data = (tmp_path / "full" / "full_0.mcap").read_bytes()
    meta_end, ends = _layout(data)
    assert len(ends) >= 8 and meta_end < ends[0][0]          # scene and settings come first
    cuts = sorted({8, 9, len(data) - 1} | {e + d for e, _ in ends for d in (-1, 0, 1, 17)}
                  | set(range(100, len(data), 997)))
    for cut in cuts:
        f = tmp_path / "cut.mcap"
        f.write_bytes(data[:cut])
        r = BagReader(f)
        complete = max([c for e, c in ends if e <= cut] + [0])
        assert r.truncated and len(r.messages_raw) == complete, (cut, len(r.messages_raw), complete)
        if cut >= meta_end:
            assert r.scene_text() == SCENE.read_text() and r.settings()["scene"] == "actuator_arm"
    # recover: a complete bag that rosbags and mcap_ros2 read, same messages
    f.write_bytes(data[:ends[4][0] + 50])
    r = recover(f, tmp_path / "rec")
    back = BagReader(tmp_path / "rec")
    assert not back.truncated and len(back.messages_raw) == ends[4][1]
    assert [m.data for m in back.messages_raw] == [m.data for m in r.messages_raw]
    assert back.scene_text() == SCENE.read_text() and back.settings() == r.settings()
    from rosbags.highlevel import AnyReader
    with AnyReader([tmp_path / "rec"]) as ar:
        assert sum(1 for c, t, raw in ar.messages() if ar.deserialize(raw, c.msgtype) is not None) == ends[4][1]


def test_reader_rejects_what_is_not_a_bag(tmp_path):
    (tmp_path / "x.mcap").write_bytes(b"not an mcap file")
    with pytest.raises(BagError, match="bad magic"):
        BagReader(tmp_path / "x.mcap")
    with pytest.raises(BagError, match="no such file or directory"):
        BagReader(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagError, match="expected one .mcap file"):
        BagReader(tmp_path / "empty")
    assert MAGIC == b"\x89MCAP0\r\n"


def test_bag_info_agrees_with_a_clean_bag_that_declared_an_unused_topic(tmp_path):
    """The node declares every topic it may record; one never written (a command topic nobody
    used) is listed in metadata.yaml with 0 messages and must not make `bag info` cry 'DIFFERS'."""
    from flexmb_io.bag.info import bag_info, format_info

    out = tmp_path / "bag"
    rec = _record(out, n=100)
    rec.declare("/flexmb_twin/commands", "std_msgs/msg/Float64MultiArray")
    rec.close()
    info = bag_info(out)
    assert info["metadata_yaml"] == {"message_count": 110, "agrees": True}
    assert "agrees with the file" in format_info(info)
