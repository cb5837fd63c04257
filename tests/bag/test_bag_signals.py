"""A ``flexmb run --mcap`` interrupted by SIGINT keeps everything; one killed by SIGKILL loses at
most its open chunk, stays readable, and ``flexmb bag recover`` makes it a complete bag again.

The run is the 846-DOF Stewart twin (real-time factor ≈ 1 on one core), so the signal lands while
it steps; the test waits until the recorder has flushed its first chunks (``metadata.yaml`` is
rewritten after each one) before signalling.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest
import yaml

from flexmb_io.bag.defaults import CHUNK_SECONDS
from flexmb_io.bag.reader import BagReader
from flexmb_io.bag.replay import replay

from bag_helpers import FLEXMB, ROOT

SCENE = "scenes/stewart_platform.yaml"


def _metadata(bag):
    path = bag / "metadata.yaml"
    if not path.is_file():
        return None
    return yaml.safe_load(path.read_text())["rosbag2_bagfile_information"]


def _start_and_wait(bag, chunks: int = 2):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    proc = subprocess.Popen(FLEXMB + ["run", SCENE, "--quiet", "--mcap", str(bag)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        meta = _metadata(bag)
        # `chunks` flushed chunks (chunk k ends near k · CHUNK_SECONDS): their messages are on disk
        if meta and meta["message_count"] and meta["duration"]["nanoseconds"] >= (chunks - 0.5) * CHUNK_SECONDS * 1e9:
            return proc
        if proc.poll() is not None:
            pytest.fail(f"flexmb run ended early ({proc.returncode}): {proc.stderr.read()}")
        time.sleep(0.05)
    proc.kill()
    pytest.fail("the recording did not start within 120 s")


def test_sigint_closes_a_complete_bag_that_replays(tmp_path):
    bag = tmp_path / "interrupted"
    proc = _start_and_wait(bag)
    time.sleep(0.1)                                        # inside an open chunk
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted at t =" in err
    r = BagReader(bag)
    assert not r.truncated, r.problem
    meta = _metadata(bag)
    counts = r.counts()
    assert meta["message_count"] == sum(counts.values())   # the final metadata.yaml, nothing lost
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]} == counts
    cmds = list(r.messages({"/flexmb_twin/commands"}))
    status = [m.decode() for m in r.messages({"/flexmb_twin/status"})]
    # the last state is recorded: one step after the last command, and it counts every command
    assert status[-1].steps == len(cmds)
    t_last_cmd = cmds[-1].log_time_ns
    assert status[-1].header.stamp.sec * 10**9 + status[-1].header.stamp.nanosec == pytest.approx(
        t_last_cmd + 1_000_000, abs=10)
    rep = replay(bag)
    assert rep.ok and rep.samples_unmatched == 0 and all(f.identical for f in rep.fields), rep.format()


def test_sigkill_loses_at_most_the_open_chunk_and_recovers(tmp_path):
    from rosbags.highlevel import AnyReader

    bag = tmp_path / "killed"
    proc = _start_and_wait(bag, chunks=3)
    time.sleep(0.1)
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    meta = _metadata(bag)                 # the last one written: after the last flushed chunk
    r = BagReader(bag)
    assert r.truncated and ("provisional footer" in r.problem or "ends inside" in r.problem), r.problem
    counts = r.counts()
    # the killed file itself is a valid MCAP up to its last flushed chunk: the standard readers read it
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(r.file, "rb") as f:
        decoded = make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
        assert sum(1 for *_, msg in decoded if msg is not None) == sum(counts.values())
    with AnyReader([bag]) as ar:
        assert sum(1 for c, t, raw in ar.messages() if ar.deserialize(raw, c.msgtype)) == sum(counts.values())
    flushed = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    # everything reported flushed is readable ...
    assert all(counts.get(t, 0) >= n for t, n in flushed.items()), (counts, flushed)
    assert sum(counts.values()) >= meta["message_count"] > 0
    # ... and chunks close every CHUNK_SECONDS of simulated time, so the open chunk held at most that
    assert r.chunks >= 3
    assert all(b - a <= CHUNK_SECONDS * 1e9 for a, b in r.chunk_spans), r.chunk_spans
    assert r.scene_text() is not None and r.settings()["source"] == "flexmb run"

    p = subprocess.run(FLEXMB + ["bag", "recover", str(bag), str(tmp_path / "recovered")], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "cut short" in p.stdout and "kept every complete chunk" in p.stdout
    back = BagReader(tmp_path / "recovered")
    assert not back.truncated and back.counts() == counts
    with AnyReader([tmp_path / "recovered"]) as ar:
        assert sum(1 for c, t, raw in ar.messages() if ar.deserialize(raw, c.msgtype)) == sum(counts.values())
    rep = replay(tmp_path / "recovered")
    assert rep.ok and all(f.identical for f in rep.fields), rep.format()
    rep = replay(bag)                     # the cut-short bag itself replays too
    assert rep.ok and rep.truncated
