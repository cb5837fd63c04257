"""``flexmb bench --workers N / --scheduler`` (issue 17): the work-precision runs as Dask tasks give
the same rows as the runs in this process — errors bit for bit, in sweep order — and the report
says how the runs were timed. No timing is asserted. One local cluster of 2 worker processes.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from benchmarks.workprecision import b1, cli, core, stewart  # noqa: E402

pytest.importorskip("distributed")

DETERMINISTIC = ("case", "family", "dt", "steps", "completed", "t_reached_s", "newton_iterations_mean",
                 "substepped_steps", "error", "error_final", "error_closed_form", "error_orientation_rad")


def _nan(x) -> bool:
    return isinstance(x, float) and math.isnan(x)


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    cli.add_arguments(p)
    return p.parse_args(list(argv))


def test_b1_rows_on_dask_equal_the_rows_in_process(client):
    variants = b1.variants(True)[:4]                 # 4 cubic el. at 4, 2, 1 ms; 8 el. at 4 ms
    ctx = b1.context(True)
    kw = dict(budget_s=0.0, max_repeats=1, line=b1._line)
    lines: list[str] = []
    remote = core.run_variants("b1", variants, True, ctx, log=lines.append, client=client, **kw)
    local = core.run_variants("b1", variants, True, ctx, log=lambda s: None, **kw)
    assert len(lines) == len(variants)
    assert [r["dt"] for r in remote] == [v.dt for v in variants]                 # sweep order kept
    for r, s in zip(remote, local):
        assert r["completed"] and r["error"] > 0
        for k in DETERMINISTIC:                     # bit for bit (NaN where the case has no such error)
            assert r[k] == s[k] or (_nan(r[k]) and _nan(s[k])), k


def test_bench_on_a_scheduler_writes_the_same_errors_and_says_how_it_timed(client, tmp_path):
    out = tmp_path / "wp"
    printed: list[str] = []
    rc = cli.run(_args("--case", "stewart", "--quick", "--no-peers", "--no-plot", "--out", str(out),
                       "--scheduler", client.scheduler.address), log=lambda *a, **k: printed.append(" ".join(map(str, a))))
    assert rc == 0, printed
    meta = json.loads((out / "workprecision_stewart.json").read_text())
    assert meta["workers"] == 2 and meta["scheduler"] == client.scheduler.address
    assert "at a time" in meta["timing"] and any("--workers 1" in n for n in meta["notes"])
    assert "up to 2 runs at a time on Dask workers" in (out / "workprecision.md").read_text()
    with (out / "workprecision_stewart.csv").open() as f:
        rows = list(csv.DictReader(f))
    local = stewart.run(True, budget_s=0.0, max_repeats=1, log=lambda s: None)
    assert len(rows) == len(local) == len(stewart.variants(True))
    for r, s in zip(rows, local):                    # the CSV's numbers as report.write_csv writes them
        for k in ("error", "error_orientation_rad", "error_final"):
            assert r[k] == f"{s[k]:.6g}", k
        assert r["completed"] == "True" and float(r["dt"]) == s["dt"]


def test_more_local_workers_than_cores_is_refused(tmp_path):
    from flexmb_core.study.cluster import default_workers

    errors: list[str] = []
    rc = cli.run(_args("--case", "b1", "--quick", "--out", str(tmp_path), "--workers", str(default_workers() + 1)),
                 log=lambda *a, **k: errors.append(" ".join(map(str, a))))
    assert rc == 1 and "more runs at a time than cores" in errors[-1]
    assert not any(tmp_path.iterdir())
    assert cli.run(_args("--workers", "0", "--out", str(tmp_path)), log=lambda *a, **k: errors.append(a[0])) == 1
    assert "--workers must be a positive integer, got 0" in errors[-1]
