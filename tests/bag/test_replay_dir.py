"""``flexmb replay DIR`` (issue 17): every bag under a directory replayed as a Dask task, one table.

The reference bags replay within their manifest tolerances; a bag pushed beyond its tolerance
(bags/boom_step copied twice and replayed with +1 % E: one copy's manifest entry allows that much,
the other has the defaults) exits 3 and names that bag; an empty directory, a bad manifest and a
listed bag that is missing are reported. One local cluster of 2 worker processes for the file.
"""

from __future__ import annotations

import json
import shutil

import pytest
import yaml

from flexmb.cli import main

from bag_helpers import ROOT

pytest.importorskip("distributed")

BAG = ROOT / "bags" / "boom_step"            # 0.4 s, replays in about a second
LOOSE = {k: 1e3 for k in ("length", "position", "angle", "velocity", "force", "energy", "converged")}


def _set(tmp_path, names, manifest: dict | None):
    d = tmp_path / "set"
    for n in names:
        shutil.copytree(BAG, d / n)
    if manifest is not None:
        (d / "manifest.yaml").write_text(yaml.safe_dump({"bags": manifest}))
    return d


def test_reference_bags_replay_on_dask_within_their_manifest_tolerances(client, tmp_path, capsys):
    out = tmp_path / "r.json"
    rc = main(["replay", str(ROOT / "bags"), "--scheduler", client.scheduler.address, "--json", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    rep = json.loads(out.read_text())
    assert rep["ok"] and rep["exit_code"] == 0 and rep["workers"] == 2
    assert rep["scheduler"] == client.scheduler.address
    manifest = yaml.safe_load((ROOT / "bags" / "manifest.yaml").read_text())["bags"]
    assert [b["bag"] for b in rep["bags"]] == sorted(manifest)          # one entry per bag
    for b in rep["bags"]:
        assert b["ok"] and b["exit_code"] == 0 and b["tolerances_from"] == "manifest"
        assert {k: b["tolerances"][k] for k in manifest[b["bag"]]["tolerances"]} == manifest[b["bag"]]["tolerances"]
        assert b["report"]["samples_compared"] > 0 and b["worst"]["worst"] <= b["worst"]["limit"]
        assert b["bag"] in text
    assert "result: every bag within tolerance (exit 0)" in text


def test_a_bag_beyond_its_tolerance_exits_3_and_is_named(client, tmp_path, capsys):
    d = _set(tmp_path, ["loose", "strict"], {"loose": {"command": "copy", "tolerances": LOOSE}})
    out = tmp_path / "r.json"
    rc = main(["replay", str(d), "--scheduler", client.scheduler.address, "--json", str(out),
               "--override", "materials.aluminium.E=70.7e9"])                       # +1 % E
    text = capsys.readouterr().out
    assert rc == 3, text
    rep = {b["bag"]: b for b in json.loads(out.read_text())["bags"]}
    assert rep["loose"]["ok"] and rep["loose"]["tolerances_from"] == "manifest"
    assert rep["loose"]["tolerances"]["force"] == 1e3
    strict = rep["strict"]
    assert not strict["ok"] and strict["exit_code"] == 3 and strict["tolerances_from"] == "defaults"
    assert not strict["worst"]["ok"] and strict["worst"]["worst"] > strict["worst"]["limit"]
    assert "result: REGRESSION in strict (exit 3)" in text
    assert "replay of " in text and "REGRESSION —" in text            # the failing bag's own report too


def test_without_any_perturbation_the_same_set_passes_in_this_process(tmp_path, capsys):
    d = _set(tmp_path, ["a", "b"], None)
    assert main(["replay", str(d), "--workers", "1", "--quiet"]) == 0
    assert capsys.readouterr().out == ""                                # --quiet: nothing when all pass


def test_empty_directory_bad_manifest_and_missing_bag(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["replay", str(empty)]) == 1
    assert f"{empty}: no bags under this directory" in capsys.readouterr().err
    d = _set(tmp_path, ["a"], {"a": {"tolerances": {"lenght": 1e-6}}})
    assert main(["replay", str(d), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert "manifest.yaml:bags.a.tolerances: unknown tolerance 'lenght'" in err
    (d / "manifest.yaml").write_text(yaml.safe_dump({"bags": {"a": {}, "gone": {"tolerances": LOOSE}}}))
    assert main(["replay", str(d), "--workers", "1"]) == 3
    text = capsys.readouterr().out
    assert "gone" in text and "listed in manifest.yaml, not found" in text and "REGRESSION in gone" in text
    (d / "manifest.yaml").unlink()
    (d / "manifest.yaml").mkdir()                  # unreadable: bad input, not a replay without tolerances
    assert main(["replay", str(d), "--workers", "1"]) == 1
    assert f"{d / 'manifest.yaml'}: cannot read the manifest" in capsys.readouterr().err
