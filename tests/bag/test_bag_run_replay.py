"""``flexmb run --mcap`` → ``flexmb replay``: round trip, what a bag holds, the readers that must
open it, and that a deliberate change of the physics fails the replay with a readable report."""

from __future__ import annotations

import json

import pytest
import yaml

from flexmb_io.bag.reader import BagReader
from flexmb_io.bag.replay import replay

from bag_helpers import ROOT, STEWART_BARS, flexmb

OUTPUTS = {"/joint_states": "sensor_msgs/msg/JointState",
           "/flexmb_twin/actuator_states": "flexmb_msgs/msg/ActuatorState",
           "/flexmb_twin/platform_pose": "geometry_msgs/msg/PoseStamped", "/tf": "tf2_msgs/msg/TFMessage",
           "/flexmb_twin/status": "flexmb_msgs/msg/TwinStatus", "/clock": "rosgraph_msgs/msg/Clock",
           "/flexmb_twin/shape": "visualization_msgs/msg/MarkerArray"}


def test_run_records_commands_every_step_and_outputs_at_the_record_rate(stewart_bag):
    r = BagReader(stewart_bag)
    assert not r.truncated
    topics = r.topics()
    assert topics == dict(OUTPUTS, **{"/flexmb_twin/commands": "std_msgs/msg/Float64MultiArray"})
    counts = r.counts()
    assert counts["/flexmb_twin/commands"] == 500                 # one per step, Δt = 1 ms over 0.5 s
    for t in ("/joint_states", "/flexmb_twin/status", "/flexmb_twin/platform_pose", "/tf", "/clock"):
        assert counts[t] == 51, t                                 # 100 Hz, t = 0 … 0.5 s
    assert counts["/flexmb_twin/shape"] == 11                     # 20 Hz
    cmds = list(r.messages({"/flexmb_twin/commands"}))
    assert [c.log_time_ns for c in cmds[:3]] == [0, 1_000_000, 2_000_000]   # logged at the step's start t_n
    assert cmds[-1].log_time_ns == 499_000_000
    act = [m.decode() for m in r.messages({"/flexmb_twin/actuator_states"})]
    # the command logged at t_n is what the state at t_n+1 reports as commanded
    by_t = {m.log_time_ns: m.decode() for m in cmds}
    st = act[10]                                                  # t = 0.1 s
    assert st.header.stamp.sec == 0 and st.header.stamp.nanosec == 100_000_000
    assert list(by_t[99_000_000].data) == list(st.commanded_lengths)
    status = [m.decode() for m in r.messages({"/flexmb_twin/status"})]
    assert all(s.converged for s in status) and status[-1].steps == 500 and status[-1].sim_time == pytest.approx(0.5)
    assert status[-1].real_time_factor > 0 and status[-1].step_wall_time > 0
    s = r.settings()
    assert s["source"] == "flexmb run" and s["until"] == "0.5" and s["scene"] == "stewart_platform_bars"
    assert json.loads(s["solver"])["dt"] == 0.001 and json.loads(s["solver"])["newton"] == "modified"
    assert r.scene_text() == (ROOT / STEWART_BARS).read_text()


def test_bags_open_with_rosbags_and_mcap_ros2(stewart_bag):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    expected = BagReader(stewart_bag).counts()
    seen: dict[str, int] = {}
    with AnyReader([stewart_bag]) as ar:                          # types from the embedded schemas
        assert ar.message_count == sum(expected.values())
        for conn, t, raw in ar.messages():
            msg = ar.deserialize(raw, conn.msgtype)
            seen[conn.topic] = seen.get(conn.topic, 0) + 1
            if conn.msgtype == "flexmb_msgs/msg/TwinStatus":
                assert msg.converged and msg.header.frame_id == "world"
            if conn.msgtype == "flexmb_msgs/msg/ActuatorState":
                assert list(msg.names) == [f"leg{k}" for k in range(1, 7)] and len(msg.axial_forces) == 6
            if conn.topic == "/tf":
                assert msg.transforms[0].child_frame_id == "platform"
    assert seen == expected
    seen = {}
    with open(next(stewart_bag.glob("*.mcap")), "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, msg in reader.iter_decoded_messages():
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            if channel.topic == "/flexmb_twin/platform_pose":
                assert msg.pose.position.z == pytest.approx(1.0, abs=0.1)
    assert seen == expected


def test_round_trip_replays_bit_identically(stewart_bag, tmp_path):
    out = tmp_path / "report.json"
    p = flexmb("replay", stewart_bag, "--json", out)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "every field within tolerance (exit 0); the replay is bit-identical" in p.stdout
    rep = json.loads(out.read_text())
    assert rep["ok"] and rep["exit_code"] == 0 and rep["steps"] == 500 and rep["commands_applied"] == 500
    assert rep["commands_rejected"] == 0 and rep["samples_unmatched"] == 0
    fields = {(f["topic"], f["field"]) for f in rep["fields"]}
    for f in (("/joint_states", "position (actuators)"), ("/joint_states", "effort"), ("/joint_states", "velocity"),
              ("/flexmb_twin/actuator_states", "axial_forces"), ("/flexmb_twin/platform_pose", "orientation"),
              ("/flexmb_twin/platform_pose", "position"), ("/tf", "transform position"),
              ("/flexmb_twin/shape", "points"), ("/flexmb_twin/status", "converged"),
              ("/flexmb_twin/status", "total_energy")):
        assert f in fields, f
    assert all(f["worst"] == 0.0 and f["identical"] for f in rep["fields"])
    # 51 × (joint_states, actuator_states, pose, tf, status, clock) + 11 shapes
    assert rep["samples_compared"] == 51 * 6 + 11


def test_material_change_fails_the_replay_with_a_readable_report(stewart_bag, tmp_path):
    p = flexmb("replay", stewart_bag, "--override", "materials.steel.E=212.1e9", "--json", tmp_path / "r.json")
    assert p.returncode == 3, p.stdout + p.stderr
    assert "result: REGRESSION" in p.stdout and "beyond tolerance" in p.stdout
    lines = {ln.split()[0] + " " + ln.split()[1]: ln for ln in p.stdout.splitlines()
             if ln.startswith("  /") and len(ln.split()) > 2}
    assert "BEYOND" in lines["/flexmb_twin/actuator_states axial_forces"]
    assert "BEYOND" in lines["/flexmb_twin/platform_pose position"]
    assert lines["/flexmb_twin/actuator_states commanded_lengths"].rstrip().endswith("ok")   # inputs unchanged
    rep = json.loads((tmp_path / "r.json").read_text())
    forces = next(f for f in rep["fields"] if f["field"] == "axial_forces")
    assert not forces["ok"] and forces["worst"] > 5 * forces["limit"] and forces["element"].startswith("leg")


def test_replay_against_a_modified_scene_file_fails(stewart_bag, tmp_path):
    from flexmb_core.scene.loader import parse_yaml

    data = parse_yaml(BagReader(stewart_bag).scene_text())
    data["point_masses"]["payload_a"]["mass"] *= 1.02                 # 2 % heavier at one vertex
    changed = tmp_path / "heavier.yaml"
    changed.write_text(yaml.safe_dump(data))
    rep = replay(stewart_bag, scene_path=str(changed))
    assert rep.exit_code == 3 and not rep.ok
    bad = {f.field for f in rep.beyond()}
    assert {"position", "orientation", "axial_forces"} <= bad
    assert str(changed) in rep.format()


def test_a_shortened_last_step_replays_exactly(tmp_path):
    out = tmp_path / "odd"
    p = flexmb("run", "scenes/actuator_arm.yaml", "--until", "0.1234", "--quiet", "--mcap", out)   # Δt = 0.01
    assert p.returncode == 0, p.stderr
    r = BagReader(out)
    assert r.counts()["/flexmb_twin/commands"] == 13                       # 12 full steps + 0.0034 s
    rep = replay(out)
    assert rep.ok and rep.steps == 13 and rep.t_end == pytest.approx(0.1234, abs=1e-15)
    assert all(f.identical for f in rep.fields)


@pytest.mark.parametrize("args, message", [
    (["--tolerance", "lenght=1e-3"], "unknown tolerance 'lenght'"),
    (["--tolerance", "force=-1"], "must be finite and ≥ 0"),
    (["--tolerance", "converged=0.5"], "tolerance converged='0.5' counts samples: expected a whole number ≥ 0"),
    (["--tolerance", "length=1e-8", "length=1e-6"], "--tolerance 'length' given twice; give each key once"),
    (["--override", "materials.titanium.E=1e11"], "the scene has no key 'materials.titanium'"),
    (["--override", "materials.steel.E=-5"], "materials.steel.E"),
])
def test_bad_replay_input_exits_1_with_a_message(stewart_bag, args, message, capsys):
    from flexmb.cli import main

    assert main(["replay", str(stewart_bag), *args]) == 1
    assert message in capsys.readouterr().err


def test_not_a_bag_and_bad_record_rate_exit_1(tmp_path, capsys):
    from flexmb.cli import main

    assert main(["replay", str(tmp_path / "missing")]) == 1
    assert "no such file or directory" in capsys.readouterr().err
    assert main(["run", "scenes/actuator_arm.yaml", "--until", "0.02", "--quiet", "--mcap", str(tmp_path / "b"),
                 "--record-rate", "0"]) == 1
    assert "--record-rate must be a positive number" in capsys.readouterr().err
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "x").write_text("keep me")
    assert main(["run", "scenes/actuator_arm.yaml", "--until", "0.02", "--quiet", "--mcap", str(tmp_path / "taken")]) == 1
    assert "never overwritten" in capsys.readouterr().err
    assert (tmp_path / "taken" / "x").read_text() == "keep me"


def test_bag_info_and_recover_verbs(stewart_bag, tmp_path):
    p = flexmb("bag", "info", stewart_bag, "--json")
    assert p.returncode == 0, p.stderr
    info = json.loads(p.stdout)
    assert info["complete"] and info["messages"] == sum(BagReader(stewart_bag).counts().values())
    assert info["metadata_yaml"]["agrees"] and info["topics"]["/tf"]["type"] == "tf2_msgs/msg/TFMessage"
    p = flexmb("bag", "info", stewart_bag)
    assert "complete" in p.stdout and "stewart_platform_bars" in p.stdout
    p = flexmb("bag", "recover", stewart_bag, tmp_path / "copy")
    assert p.returncode == 0 and "complete already" in p.stdout
    assert BagReader(tmp_path / "copy").counts() == BagReader(stewart_bag).counts()
