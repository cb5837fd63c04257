"""A recording written before this version's changes still reads and replays (issue 14): the
boom_step reference bag as recorded on 2026-11-23 — by the hand-written CDR codec that rosbags'
type store has since replaced, and before the per-member compile changed the frame elements' data
at roundoff — read by the standard readers and replayed within its manifest tolerances (no longer
bit for bit: ≤ 1e-12 of each field's peak)."""

from __future__ import annotations

from pathlib import Path

from flexmb_io.bag.reader import BagReader
from flexmb_io.bag.regenerate import load_manifest
from flexmb_io.bag.replay import replay

from bag_helpers import ROOT

OLD = Path(__file__).resolve().parents[1] / "data" / "bags" / "boom_step_recorded_2026-11-23"


def test_a_bag_recorded_before_the_changes_reads_and_replays_within_its_tolerances():
    from rosbags.highlevel import AnyReader

    r = BagReader(OLD)
    assert not r.truncated and len(r.messages_raw) == 2013
    with AnyReader([OLD]) as ar:
        assert sum(1 for c, t, raw in ar.messages() if ar.deserialize(raw, c.msgtype)) == 2013
    tol = load_manifest(ROOT / "bags")["boom_step"]["tolerances"]
    rep = replay(OLD, tolerances=tol)
    assert rep.ok, rep.format()
    assert rep.samples_compared > 0 and rep.commands_rejected == 0
    for f in rep.fields:
        if f.kind in ("force", "energy") and f.peak > 0:
            assert f.worst <= 1e-11 * f.peak, (f.topic, f.field, f.worst, f.peak)
