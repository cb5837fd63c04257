"""``flexmb sweep`` (issue 17): a parameter study on Dask distributed.

Every cluster here is local (2 worker processes on 127.0.0.1) and every run short (the bar-leg
Stewart twin, 50–300 steps), so the file stays within ~1 min on 2 shared cores.
"""

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.scene.loader import parse_yaml
from flexmb_core.scene.overrides import OverrideError, apply_overrides
from flexmb_core.study.design import design, latin_hypercube, parse_param
from flexmb_core.study.runs import flatten, make_spec, run_one
from flexmb_core.study.sweep import plan, sweep
from flexmb_core.study.table import read_csv

pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parents[2]
SCENE = "scenes/stewart_platform_bars.yaml"
E_VALUES = ("2.0e11", "2.1e11", "2.2e11")
MASSES = ("3.0", "4.0", "5.0")


def _flat_outputs(outputs: dict) -> dict:
    return dict(leaf for name, v in outputs.items() for leaf in flatten(name, v))


# -- the design ------------------------------------------------------------------------------------

def test_lists_are_crossed_first_param_slowest():
    runs = design([parse_param("a.b=1,2"), parse_param("c=x,y,z")])
    assert runs == [{"a.b": 1, "c": "x"}, {"a.b": 1, "c": "y"}, {"a.b": 1, "c": "z"},
                    {"a.b": 2, "c": "x"}, {"a.b": 2, "c": "y"}, {"a.b": 2, "c": "z"}]
    p = parse_param("members.leg1.actuator.stroke=[0.6,1.6],[0.7, 1.5]")
    assert p.values == ([0.6, 1.6], [0.7, 1.5])


def test_latin_hypercube_is_seeded_reproducible_stratified_and_within_bounds():
    params = [parse_param("materials.steel.E=2.0e11:2.2e11"), parse_param("materials.steel.eta=1e5:1e7"),
              parse_param("members.leg1.elements=2:5")]
    n = 16
    a = latin_hypercube(params, n, seed=7)
    assert a.shape == (n, 3)
    assert np.array_equal(a, latin_hypercube(params, n, seed=7))            # same seed, same points
    assert not np.array_equal(a, latin_hypercube(params, n, seed=8))
    for j, p in enumerate(params[:2]):
        assert np.all((a[:, j] >= p.low) & (a[:, j] <= p.high))
        strata = np.floor(n * (a[:, j] - p.low) / (p.high - p.low)).astype(int)
        assert sorted(strata) == list(range(n))                              # one sample per stratum
    assert set(a[:, 2]) <= {2.0, 3.0, 4.0, 5.0} and len(set(a[:, 2])) == 4   # integers over 2…5
    for dist in ("loguniform", "normal"):
        b = latin_hypercube(params[:2], 64, distribution=dist, seed=1)
        assert np.all((b >= [2.0e11, 1e5]) & (b <= [2.2e11, 1e7])), dist
    logs = np.log(latin_hypercube(params[1:2], n, distribution="loguniform", seed=3)[:, 0])
    assert sorted(np.floor(n * (logs - np.log(1e5)) / np.log(100.0)).astype(int)) == list(range(n))
    runs = design(params[:1] + [parse_param("solver.integrator=newmark,generalized_alpha")], samples=4, seed=7)
    assert len(runs) == 8 and [r["materials.steel.E"] for r in runs[:4]] == [r["materials.steel.E"] for r in runs[4:]]
    assert isinstance(design(params[2:], samples=3)[0]["members.leg1.elements"], int)


def test_run_keys_are_stable_and_follow_the_effective_scene():
    items = ["materials.steel.E=2.0e11:2.2e11"]
    _, s1 = plan(ROOT / SCENE, items, samples=4, seed=3, until=0.05)
    _, s2 = plan(ROOT / SCENE, items, samples=4, seed=3, until=0.05)
    assert [s.key for s in s1] == [s.key for s in s2] and len({s.key for s in s1}) == 4
    _, s3 = plan(ROOT / SCENE, items, samples=4, seed=3, until=0.1)
    assert not {s.key for s in s1} & {s.key for s in s3}                     # until is part of the key
    for s in s1:
        assert parse_yaml(s.scene_yaml)["materials"]["steel"]["E"] == s.params["materials.steel.E"]


@pytest.mark.parametrize("items, kw, message", [
    (["materials.steel.E"], {}, "expected KEY.PATH=VALUES"),
    (["materials.steel.E=2:1"], {"samples": 3}, "a range needs finite bounds LO < HI, got 2:1"),
    (["materials.steel.E=2e11:3e11"], {}, "is a range: give --samples N"),
    (["materials.steel.E=2e11,3e11"], {"samples": 3}, "--samples needs at least one range parameter"),
    (["materials.titanium.E=1e11"], {}, "the scene has no key 'materials.titanium' (has ['steel'])"),
    (["materials.steel.E=1,2", "materials.steel.E=3"], {}, "given more than once"),
    (["materials.steel.E=nan:2e11"], {"samples": 2}, "a range needs two numbers LO:HI (e.g. 2.0e11:2.2e11), "
                                                     "got 'nan:2e11'"),
    (["materials.steel.E=1:2:3"], {"samples": 2}, "a range needs two numbers LO:HI"),
])
def test_bad_params_are_refused_before_any_run(items, kw, message):
    with pytest.raises(OverrideError) as exc:
        plan(ROOT / SCENE, items, until=0.05, **kw)
    assert message in str(exc.value)


def test_an_edit_through_a_yaml_anchor_changes_only_the_named_entry():
    data = parse_yaml((ROOT / SCENE).read_text())
    assert data["members"]["leg1"]["actuator"] is data["members"]["leg2"]["actuator"]   # shared by <<: *leg
    assert apply_overrides(data, ["members.leg1.actuator.stroke=[0.7, 1.5]", "solver.dt=5e-4"]) == {"dt": 5e-4}
    assert data["members"]["leg1"]["actuator"]["stroke"] == [0.7, 1.5]
    assert data["members"]["leg2"]["actuator"]["stroke"] == [0.65, 1.65]
    with pytest.raises(OverrideError, match=r"--override 'supports.9.type=ball': index 9 out of range \(list of 6\)"):
        apply_overrides(data, ["supports.9.type=ball"])
    with pytest.raises(OverrideError) as exc:          # the flag and item, not the value's line and column
        apply_overrides(data, ["materials.steel.E=[1,"])
    assert str(exc.value).startswith("--override 'materials.steel.E=[1,': the value is not valid YAML (not valid YAML: ")


# -- one run ---------------------------------------------------------------------------------------

def test_a_row_holds_max_min_rms_over_the_sampled_times(tmp_path):
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene.loader import scene_from_dict
    from flexmb_core.simulator import Simulator

    base = parse_yaml((ROOT / SCENE).read_text())
    spec = make_spec(base, {"materials.steel.E": 2.0e11}, source=SCENE, until=0.05,
                     outputs=("leg1_force", "platform.position"), every=4)
    row = run_one(spec)
    assert row["ok"] and row["converged"] and row["samples"] == 1 + 12 + 1          # t0, every 4th step, the end
    assert set(row["max"]) == {"leg1_force", "platform.position.0", "platform.position.1", "platform.position.2"}
    sim = Simulator(compile_scene(scene_from_dict(parse_yaml(spec.scene_yaml), overrides={"until": 0.05})))
    sim.warmup()
    sim.initialize()
    seen = [_flat_outputs(sim.outputs())]
    sim.run(0.05, callback=lambda s, r: seen.append(_flat_outputs(s.outputs())) if s.stats.steps % 4 == 0
            or s.stats.steps == 50 else None)
    for k in row["max"]:
        v = np.array([s[k] for s in seen])
        assert row["max"][k] == v.max() and row["min"][k] == v.min() and row["final"][k] == v[-1]
        assert math.isclose(row["rms"][k], float(np.sqrt(np.mean(v**2))), rel_tol=1e-13)


# -- sweeps on the cluster -------------------------------------------------------------------------

def test_3x3_sweep_equals_9_sequential_flexmb_runs(tmp_path):
    from flexmb_core.cli import main

    out = tmp_path / "sweep"
    p = subprocess.run([sys.executable, "-m", "flexmb_core.cli", "sweep", SCENE,
                        "--param", f"materials.steel.E={','.join(E_VALUES)}",
                        f"point_masses.payload_a.mass={','.join(MASSES)}",
                        "--until", "0.05", "--workers", "2", "--out", str(out), "--quiet"],
                       capture_output=True, text=True, cwd=ROOT, timeout=180)
    assert p.returncode == 0, p.stderr
    table = read_csv(out / "sweep.csv")
    assert len(table) == 9 and len(list((out / "runs").glob("*.json"))) == 9
    text = (ROOT / SCENE).read_text()
    for i, (e, m) in enumerate((e, m) for e in E_VALUES for m in MASSES):
        row = json.loads((out / "runs" / f"{table[i]['key']}.json").read_text())
        assert row["params"] == {"materials.steel.E": float(e), "point_masses.payload_a.mass": float(m)}
        assert table[i]["materials.steel.E"] == repr(float(e)) and table[i]["ok"] == "true"
        # the same edits made by hand to the scene file, run by `flexmb run`
        scene = tmp_path / f"s{i}.yaml"
        scene.write_text(text.replace("E: 210.0e9", f"E: {e}").replace("mass: 3.3333333333}", f"mass: {m}}}", 1))
        assert main(["run", str(scene), "--until", "0.05", "--json", str(tmp_path / f"r{i}.json"), "--quiet"]) == 0
        ref = json.loads((tmp_path / f"r{i}.json").read_text())
        final = _flat_outputs(ref["outputs"])
        assert row["final"] == final                                               # bit-identical
        for k in ("steps", "newton_iterations_mean", "newton_iterations_max", "unconverged_steps",
                  "max_relative_residual", "sim_time_s"):
            assert row["summary"][k] == ref[k], k
        assert row["tracking"] == {k: v for k, v in ref["tracking"].items() if k != "output"}
        for k, v in final.items():                                                 # the CSV round-trips
            assert float(table[i][f"final.{k}"]) == v
    import pyarrow.parquet as pq

    pt = pq.read_table(out / "sweep.parquet").to_pylist()
    assert [r["final.leg1_force"] for r in pt] == [float(r["final.leg1_force"]) for r in table]
    assert (out / "sweep.png").stat().st_size > 10_000


def test_a_killed_worker_loses_no_run_and_a_rerun_computes_nothing(client, tmp_path):
    items = ["materials.steel.E=2.0e11,2.1e11,2.2e11", "point_masses.payload_a.mass=3.0,4.0,5.0"]
    killed: dict = {}

    def kill_a_busy_worker(ev):
        if killed:
            return
        busy = [(addr, keys) for addr, keys in client.processing().items() if keys]
        if busy:
            addr, keys = busy[0]
            pid = client.run(os.getpid, workers=[addr])[addr]
            os.kill(pid, signal.SIGKILL)
            killed.update(pid=pid, keys={k.removeprefix("flexmb-run-") for k in keys})

    res = sweep(ROOT / SCENE, items, until=0.3, out=tmp_path, scheduler=client, progress=kill_a_busy_worker)
    assert killed, "no worker was busy when the first run finished"
    assert res.computed == 9 and res.failed == 0 and all(r["ok"] for r in res.rows)
    for key in killed["keys"]:                  # what ran on the killed worker ran again elsewhere
        row = json.loads((tmp_path / "runs" / f"{key}.json").read_text())
        assert row["ok"] and not row["worker"].endswith(f":{killed['pid']}")
    runs = sorted((tmp_path / "runs").glob("*.json"))
    assert len(runs) == 9
    mtimes = [p.stat().st_mtime_ns for p in runs]
    again = sweep(ROOT / SCENE, items, until=0.3, out=tmp_path, scheduler=client)
    assert again.computed == 0 and again.cached == 9
    assert [p.stat().st_mtime_ns for p in runs] == mtimes
    assert again.records == res.records


def test_a_failing_run_is_a_row_with_its_error(client, tmp_path):
    res = sweep(ROOT / SCENE, ["materials.steel.E=2.1e11,-1", "solver.max_iterations=20,1"], until=0.05,
                out=tmp_path, scheduler=client)
    assert res.computed == 4 and res.failed == 3
    rows = {(r["params"]["materials.steel.E"], r["params"]["solver.max_iterations"]): r for r in res.rows}
    assert rows[(2.1e11, 20)]["ok"]
    for it in (20, 1):
        bad = rows[(-1, it)]
        assert not bad["ok"] and bad["error_kind"] == "scene"
        assert bad["error"] == (f"scene error: {ROOT / SCENE}:materials.steel.E: expected a positive number (Pa), "
                                "got -1.0")
    slow = rows[(2.1e11, 1)]             # one Newton iteration cannot meet the tolerance
    assert not slow["ok"] and slow["error_kind"] == "convergence" and "did not converge" in slow["error"]
    table = read_csv(tmp_path / "sweep.csv")
    assert [r["ok"] for r in table] == ["true", "false", "false", "false"]
    assert table[2]["final.leg1_force"] == "" and table[2]["error"].startswith("scene error:")
    assert len(list((tmp_path / "runs").glob("*.json"))) == 4     # deterministic failures are stored too


def test_bad_worker_count_exits_1(capsys):
    from flexmb_core.cli import main

    assert main(["sweep", SCENE, "--param", "materials.steel.E=2e11", "--workers", "0", "--until", "0.01",
                 "--quiet"]) == 1
    assert "--workers must be a positive integer, got 0" in capsys.readouterr().err
