"""Smoke test of ``flexmb bench`` (work-precision reports): the B1 quick sweep into a temp dir.

Checks the CSV schema, that the dynamic error falls with Δt refinement (a physical property, order 2
for generalized-α), the PNG and the markdown. Never asserts a speed.
"""

from __future__ import annotations

import csv
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from benchmarks.workprecision import core  # noqa: E402


@pytest.fixture(scope="module")
def quick_b1(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wp")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    env.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))
    proc = subprocess.run([sys.executable, "-m", "flexmb.cli", "bench", "--case", "b1", "--quick", "--no-peers",
                           "--out", str(out)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


def _rows(out: Path) -> list[dict]:
    with (out / "workprecision_b1.csv").open() as f:
        return list(csv.DictReader(f))


def test_csv_has_every_column_and_completed_runs(quick_b1):
    with (quick_b1 / "workprecision_b1.csv").open() as f:
        header = next(csv.reader(f))
    assert tuple(header) == core.COLUMNS
    rows = _rows(quick_b1)
    assert len(rows) >= 4
    for r in rows:
        assert r["case"] == "b1" and r["code"] == "flexmb"
        assert r["completed"] == "True", r["note"]
        assert float(r["wall_per_sim_s"]) > 0 and math.isfinite(float(r["error"]))
        assert float(r["rtf"]) == pytest.approx(1.0 / float(r["wall_per_sim_s"]), rel=1e-4)


def test_error_falls_with_dt(quick_b1):
    fam = sorted((r for r in _rows(quick_b1) if r["family"].startswith("4×cubic, gen-α ρ∞=0.8, modified")),
                 key=lambda r: -float(r["dt"]))
    dts = [float(r["dt"]) for r in fam]
    errs = [float(r["error"]) for r in fam]
    assert len(fam) >= 3 and dts == sorted(dts, reverse=True)
    assert all(b < a for a, b in zip(errs, errs[1:])), list(zip(dts, errs))
    # generalized-α is second order: 4 → 2 ms divides the error by ≈ 4
    assert errs[0] / errs[1] > 3.0


def test_final_error_is_the_settled_mesh_error(quick_b1):
    rows = {(r["family"], float(r["dt"])): float(r["error_final"]) for r in _rows(quick_b1)}
    four = rows[("4×cubic, gen-α ρ∞=0.8, modified Newton", 1e-3)]
    eight = rows[("8×cubic, gen-α ρ∞=0.8, modified Newton", 1e-3)]
    assert eight < four < 1e-5          # README: 1.5e-6 (4 el.), 4e-7 (8 el.) of the converged solution


def test_png_and_markdown(quick_b1):
    png = quick_b1 / "workprecision_b1.png"
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    md = (quick_b1 / "workprecision.md").read_text()
    assert "B1 cantilever" in md and "workprecision_b1.png" in md


def test_missing_reference_names_the_fix(tmp_path):
    with pytest.raises(FileNotFoundError, match="--make-reference"):
        core.read_reference(tmp_path / "b1.csv")


def test_history_error_is_nan_when_a_mark_is_missing():
    import numpy as np

    ref_t = np.array([0.0, 0.1, 0.2])
    ref = np.zeros((3, 3))
    samples = {0: np.zeros(3), 1: np.array([0.0, 3.0, 4.0])}
    err, final, n = core.history_error(samples, ref_t, ref, 0.1, 0.1, scale=5.0)
    assert (err, final, n) == (1.0, 1.0, 2)
    assert math.isnan(core.history_error(samples, ref_t, ref, 0.1, 0.2)[0])
