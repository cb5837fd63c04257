"""Regression: every reference recording in ``bags/`` replays within its manifest tolerances.

A failure here means the solver's results changed. If the change is intended, re-record with
``bags/regenerate.sh`` and commit the new bags with ``bags/manifest.yaml``.
"""

from __future__ import annotations

import warnings

import pytest
import yaml

from flexmb_io.bag.reader import BagReader
from flexmb_io.bag.recorder import scene_sha256
from flexmb_io.bag.regenerate import load_manifest
from flexmb_io.bag.replay import replay

from bag_helpers import ROOT

BAGS = ROOT / "bags"
MANIFEST = load_manifest(BAGS)


def test_manifest_lists_exactly_the_bags_in_the_directory():
    dirs = {p.name for p in BAGS.iterdir() if p.is_dir()}
    assert dirs == set(MANIFEST), f"bags/ holds {sorted(dirs)}, the manifest lists {sorted(MANIFEST)}"
    assert {"stewart_bars_appendix", "boom_step"} <= dirs
    total = sum(f.stat().st_size for d in dirs for f in (BAGS / d).iterdir())
    assert total < 5e6, f"reference bags take {total / 1e6:.1f} MB (keep them to a few MB)"
    for name, entry in MANIFEST.items():
        for key in ("command", "scene", "scene_sha256", "flexmb_version", "tolerances", "date", "messages"):
            assert key in entry, f"manifest entry {name} lacks {key}"
        assert entry["command"].startswith("flexmb run ") and f"--mcap bags/{name}" in entry["command"]


@pytest.mark.parametrize("name", sorted(MANIFEST))
def test_reference_bag_replays_within_tolerance(name):
    entry = MANIFEST[name]
    bag = BAGS / name
    r = BagReader(bag)
    assert not r.truncated, r.problem
    assert len(r.messages_raw) == entry["messages"]
    text = r.scene_text()
    assert scene_sha256(text) == entry["scene_sha256"] == r.settings()["scene_sha256"]
    current = ROOT / entry["scene"]
    if current.is_file() and scene_sha256(current.read_text()) != entry["scene_sha256"]:
        warnings.warn(f"{entry['scene']} changed since bags/{name} was recorded (the bag replays its own copy); "
                      "regenerate if the change is meant to be covered", stacklevel=1)
    rep = replay(bag, tolerances=entry["tolerances"])
    assert rep.ok, "\n" + rep.format()
    assert rep.samples_compared > 0 and rep.commands_rejected == 0
    assert rep.t_end == pytest.approx(entry["t_end_s"], abs=1e-9)


def test_the_hard_case_is_hard():
    """boom_step: a step in commanded length — an impulsive load, long Newton solves, ringing."""
    r = BagReader(BAGS / "boom_step")
    status = [m.decode() for m in r.messages({"/flexmb_twin/status"})]
    forces = [max(abs(f) for f in m.decode().axial_forces) for m in r.messages({"/flexmb_twin/actuator_states"})]
    assert len(status) == 401                                      # every step recorded
    assert max(s.newton_iterations for s in status[:50]) <= 2      # before the step at t = 0.05 s
    assert max(s.newton_iterations for s in status) >= 10          # after it
    assert max(s.kinetic_energy for s in status) > 10.0 and max(forces) > 1e4 > 100 * max(forces[:50])
    assert all(s.converged for s in status)


@pytest.mark.parametrize("name", sorted(MANIFEST))
def test_reference_bag_is_not_fragile(name):
    """A reference must not hinge on round-off: a tighter Newton tolerance (other iteration counts,
    other round-off) still replays within the manifest tolerances. A recording whose steps may or
    may not be retried in sub-steps fails here (see scenes/boom_step.yaml)."""
    entry = MANIFEST[name]
    tol = float(yaml.safe_load(BagReader(BAGS / name).scene_text())["solver"]["tolerance"])
    rep = replay(BAGS / name, tolerances=entry["tolerances"], overrides=[f"solver.tolerance={tol / 3:.6g}"])
    assert rep.ok, "\n" + rep.format()


def test_reference_bags_open_with_rosbags():
    from rosbags.highlevel import AnyReader

    for name, entry in MANIFEST.items():
        with AnyReader([BAGS / name]) as ar:
            n = sum(1 for c, t, raw in ar.messages() if ar.deserialize(raw, c.msgtype) is not None)
        assert n == entry["messages"], name


def test_regenerate_rerecords_checks_and_updates_the_manifest(tmp_path):
    from bag_helpers import flexmb

    bags = tmp_path / "bags"
    bags.mkdir()
    scene = ROOT / "scenes" / "actuator_arm.yaml"
    (bags / "manifest.yaml").write_text(yaml.safe_dump({"bags": {"tiny": {
        "description": "test", "command": f"flexmb run {scene} --until 0.05 --quiet --mcap bags/tiny",
        "scene": str(scene), "tolerances": {"length": 1e-9}}}}))
    p = flexmb("bag", "regenerate", "--dir", bags)
    assert p.returncode == 0, p.stdout + p.stderr
    # 5 commands (Δt = 10 ms), 6 × (joint_states, actuator_states, status, clock), shape at 0 and 0.05 s
    assert "tiny: 31 messages" in p.stdout and "replay bit-identical" in p.stdout
    text = (bags / "manifest.yaml").read_text()
    assert text.startswith("# Reference recordings of flexmb")
    entry = yaml.safe_load(text)["bags"]["tiny"]
    assert entry["scene_sha256"] == scene_sha256(scene.read_text()) and entry["t_end_s"] == pytest.approx(0.05)
    assert entry["tolerances"] == {"length": 1e-9} and entry["description"] == "test"
    assert sorted(p.name for p in (bags / "tiny").iterdir()) == ["metadata.yaml", "tiny_0.mcap"]
    assert replay(bags / "tiny").ok
    p = flexmb("bag", "regenerate", "--dir", bags, "--only", "nope")
    assert p.returncode == 1 and "not in" in p.stderr
