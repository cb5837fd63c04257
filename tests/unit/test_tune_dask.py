"""``flexmb tune`` on Dask (issue 17): the runs give the sequential search's outputs bit for bit, and
the search on Dask chooses what the sequential one chooses from the same measurements.

Real wall times differ from run to run (the sequential search itself can choose differently twice
on a loaded machine), so the search-level comparison gives both searches the same deterministic
stand-in for a run's time (``modelled_cost``: steps × a factor per fidelity); the errors are the
real ones. One local cluster of 2 worker processes for the file; short horizons (0.2–0.4 s of the
actuator arm, Δt = 10 ms).
"""

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.cli import main
from flexmb_core.scene.loader import parse_yaml
from flexmb_core.tune import InProcess, Job, Measured, OnDask, _candidates, measure, reference_scene, tune, Trial

pytest.importorskip("distributed")

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "actuator_arm.yaml"


def modelled_cost(job: Job) -> Measured:
    """``measure(job)`` with its times replaced by a deterministic model of the cost: steps × 1.8 for
    full Newton × 1.5 for a frame (not bar) actuator, 10 µs a unit — the same wherever it runs."""
    m = measure(job)
    if not m.message:
        full = job.scene["solver"].get("newton", "full") == "full"
        frame = (job.scene["members"]["lift"].get("actuator") or {}).get("variant", "frame") == "frame"
        m.wall = m.cpu = 1e-5 * m.steps * (1.8 if full else 1.0) * (1.5 if frame else 1.0)
    return m


def test_runs_on_dask_equal_the_sequential_runs_bit_for_bit(client):
    data = parse_yaml(SCENE.read_text())
    base = Trial("as declared", data)
    scenes = [reference_scene(data), data] + [s for _, s in _candidates(base, base)]
    jobs = [Job(copy.deepcopy(s), 0.2, 0.04, "arm") for s in scenes]
    seen = []
    remote = OnDask(client).runs(jobs, lambda i, m: seen.append(i))
    local = InProcess().runs(jobs, lambda i, m: None)
    assert sorted(seen) == list(range(len(jobs))) and len(jobs) >= 5     # every run reported once
    for r, s in zip(remote, local):
        assert not r.message and r.steps == s.steps > 0
        assert r.series.keys() == s.series.keys()
        for name, (kind, y) in s.series.items():
            assert r.series[name][0] == kind and np.array_equal(r.series[name][1], y), name


def test_search_on_dask_chooses_what_the_sequential_search_chooses(client):
    data = parse_yaml(SCENE.read_text())
    seen_remote, seen_local = [], []
    remote = tune(copy.deepcopy(data), 1e-4, 0.4, source="arm", evaluator=OnDask(client, task=modelled_cost),
                  progress=lambda t: seen_remote.append(t.label))
    local = tune(copy.deepcopy(data), 1e-4, 0.4, source="arm", evaluator=InProcess(task=modelled_cost),
                 progress=lambda t: seen_local.append(t.label))
    assert remote.best.label == local.best.label and remote.best.ok
    assert [t.label for t in remote.trials] == [t.label for t in local.trials]
    assert len(remote.trials) >= 6                                  # several rounds were searched
    for a, b in zip(remote.trials, local.trials):
        assert a.errors == b.errors and a.ok == b.ok, a.label      # measured errors, bit for bit
        assert a.wall_per_sim_s == b.wall_per_sim_s, a.label
    assert remote.best.scene == local.best.scene
    assert (remote.workers, remote.scheduler) == (2, client.scheduler.address)
    assert (local.workers, local.scheduler) == (1, "")
    # on Dask every decision used a wall time taken alone: the chosen one and the baseline were re-timed
    assert remote.best.timing == "re-timed" and remote.baseline.timing == "re-timed"
    assert {t.timing for t in local.trials} == {"in-process"}
    assert set(seen_local) == {t.label for t in local.trials} <= set(seen_remote)


def test_tune_command_on_a_scheduler_writes_workers_scheduler_and_timing(client, tmp_path):
    args = [str(SCENE), "--tol", "1e-4", "--until", "0.4", "--quiet"]
    assert main(["tune", *args, "--out", str(tmp_path / "d"), "--scheduler", client.scheduler.address]) == 0
    assert main(["tune", *args, "--out", str(tmp_path / "s"), "--workers", "1"]) == 0
    d = json.loads((tmp_path / "d" / "actuator_arm_tune.json").read_text())
    s = json.loads((tmp_path / "s" / "actuator_arm_tune.json").read_text())
    assert d["workers"] == 2 and d["scheduler"] == client.scheduler.address
    assert s["workers"] == 1 and s["scheduler"] == ""
    assert d["within_tolerance"] and d["trials"][0]["label"] == "as declared"
    chosen = next(t for t in d["trials"] if t["label"] == d["chosen"])
    assert chosen["timing"] == "re-timed" and max(chosen["errors"][k] for k in ("arm_end", "arm_mid")) <= 1e-4
    assert {t["timing"] for t in d["trials"]} <= {"parallel", "re-timed"}
    assert {t["timing"] for t in s["trials"]} == {"in-process"}
    for t in d["trials"]:
        assert math.isfinite(t["screen_cpu_per_sim_s"]) and t["screen_cpu_per_sim_s"] > 0
    # the errors do not depend on where a run happened (the searches may take other paths: timings)
    errs = {t["label"]: t["errors"] for t in s["trials"]}
    common = [t for t in d["trials"] if t["label"] in errs]
    assert len(common) >= 4 and all(t["errors"] == errs[t["label"]] for t in common)
    md = (tmp_path / "d" / "actuator_arm_tune.md").read_text()
    assert "| timed |" in md and "re-timed" in md and "Runs on Dask (2 workers" in md


def test_bad_workers_is_refused_before_any_cluster(capsys):
    assert main(["tune", str(SCENE), "--tol", "1e-4", "--workers", "0"]) == 1
    assert "--workers must be a positive integer, got 0" in capsys.readouterr().err
