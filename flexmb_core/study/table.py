"""Where a study keeps its results: one JSON file per run (``runs/<key>.json``, written as each run
finishes, atomically) and one table over all runs (``sweep.csv``, ``sweep.parquet``).

Table columns, in order: ``index`` (position in the design), ``key`` (the run's sha256), one column
per ``--param`` (named by its key path), ``ok``, ``completed``, ``converged``, ``error``,
``error_kind``, the ``flexmb run --json`` metrics (``steps`` … ``integrator``), ``task_wall_s``
(load + compile + warm-up + run on the worker), ``samples``, ``worker``, then per chosen output part
``final.<part>``, ``max.<part>``, ``min.<part>``, ``rms.<part>`` and, for a platform with a command
program, ``tracking.<metric>``.
"""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path
from typing import Any

from .runs import STATS, SUMMARY_KEYS

HEAD = ("index", "key")
FLAGS = ("ok", "completed", "converged", "error", "error_kind")
TAIL = ("task_wall_s", "samples", "worker")


def run_path(out: Path, key: str) -> Path:
    return Path(out) / "runs" / f"{key}.json"


def load_run(out: Path, key: str) -> dict | None:
    """The stored row of run ``key``, or None when absent or unreadable (then it is recomputed)."""
    path = run_path(out, key)
    try:
        row = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return row if isinstance(row, dict) and row.get("key") == key else None


def save_run(out: Path, row: dict) -> Path:
    """Write a row atomically (a killed sweep leaves whole files or none)."""
    path = run_path(out, row["key"])
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(row, indent=1, allow_nan=True) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path


def flat_record(index: int, row: dict, param_keys: list[str]) -> dict[str, Any]:
    """One table row (column → scalar) from a run's row."""
    rec: dict[str, Any] = {"index": index, "key": row["key"]}
    params = row.get("params", {})
    rec.update({k: _scalar(params.get(k)) for k in param_keys})
    rec.update({k: row.get(k) for k in FLAGS})
    summary = row.get("summary") or {}
    rec.update({k: summary.get(k) for k in SUMMARY_KEYS})
    rec.update({k: row.get(k) for k in TAIL})
    for stat in STATS:
        rec.update({f"{stat}.{k}": v for k, v in (row.get(stat) or {}).items()})
    rec.update({f"tracking.{k}": v for k, v in (row.get("tracking") or {}).items()})
    return rec


def _scalar(v: Any) -> Any:
    return v if v is None or isinstance(v, (bool, int, float, str)) else json.dumps(v)


def columns(records: list[dict]) -> list[str]:
    """Every column in first-seen order (failed runs lack the output columns)."""
    return list(dict.fromkeys(k for r in records for k in r))


def write_csv(path: Path, records: list[dict]) -> Path:
    cols = columns(records)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for r in records:
            w.writerow(["" if r.get(c) is None else _cell(r[c]) for c in cols])
    return path


def _cell(v: Any) -> Any:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)                              # round-trips exactly
    return v


def write_parquet(path: Path, records: list[dict]) -> Path | None:
    """The table as Parquet, or None when ``pyarrow`` is not installed (extra ``[cluster]``)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    cols = columns(records)
    arrays = {c: _column(pa, [r.get(c) for r in records]) for c in cols}
    pq.write_table(pa.table(arrays), path)
    return path


def _column(pa, values: list[Any]):
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return pa.array(values, type=pa.bool_())
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pa.array(values, type=pa.int64())
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        return pa.array([None if v is None else float(v) for v in values], type=pa.float64())
    return pa.array([None if v is None else (v if isinstance(v, str) else json.dumps(v)) for v in values],
                    type=pa.string())


def read_csv(path: Path) -> list[dict[str, str]]:
    """The table back as strings (tests, scripts)."""
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def number(cell: str) -> float:
    """A CSV cell as a float (empty → nan)."""
    return float(cell) if cell not in ("", None) else math.nan
