"""``flexmb sweep``: a parameter study of a scene, each run a task on Dask distributed.

1. :func:`plan` turns ``--param`` items into a design (:mod:`.design`) and every design point into
   a :class:`~.runs.RunSpec` keyed by the hash of its effective scene (:mod:`.runs`).
2. :func:`execute` loads the runs already stored under ``OUT/runs/`` and submits the others to a
   Dask cluster — an in-process ``LocalCluster`` (worker processes, one thread each, on 127.0.0.1)
   or the scheduler at ``--scheduler ADDRESS`` — and stores each row as it arrives. A worker that
   dies mid-run loses nothing: the scheduler reschedules its task on another worker (up to
   ``distributed.scheduler.allowed-failures`` deaths); ``retries`` re-runs a task that raised
   outside its run (:func:`~.runs.run_one` turns a run's own errors into rows). A run that fails is
   a row with its error, stored; a run the cluster could not complete (``error_kind: lost``) or that
   met an unforeseen error (``error_kind: unexpected``, a bug) is a row too, but is not stored, so
   the next sweep tries it again.
3. :func:`write_results` writes ``sweep.csv``, ``sweep.parquet`` (with pyarrow), ``sweep.png``
   (with matplotlib) and ``sweep.json`` (the settings and counts of the sweep).

Dask is imported inside :func:`execute` only: the rest of flexmb works without it.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from ..errors import FlexmbError, SceneError, name_list
from .cluster import connect, default_workers
from .design import Param, design, parse_param
from .runs import RunSpec, make_spec, run_one
from .table import flat_record, load_run, save_run, write_csv, write_parquet

DEFAULT_OUT = "build/sweep"


@dataclass
class SweepEvent:
    """What the progress callback receives after each run."""

    done: int
    total: int
    computed: int
    cached: int
    failed: int
    row: dict
    spec: RunSpec
    stored: bool                       # the row came from OUT/runs/ (nothing computed)


@dataclass
class SweepResult:
    out: Path
    params: list[Param]
    specs: list[RunSpec]               # one per design point, in design order
    rows: list[dict | None]            # the same order; None: not finished (interrupted)
    computed: int = 0
    cached: int = 0
    failed: int = 0
    wall_time_s: float = 0.0
    workers: int = 0
    scheduler: str = ""
    interrupted: bool = False
    files: dict[str, str] = field(default_factory=dict)

    @property
    def records(self) -> list[dict]:
        keys = [p.key for p in self.params]
        return [flat_record(i, r, keys) for i, r in enumerate(self.rows) if r is not None]


def plan(scene_path: str | Path, param_items: list[str], *, samples: int | None = None,
         distribution: str = "uniform", seed: int = 0, until: float | None = None,
         outputs: list[str] | None = None, every: int = 1) -> tuple[list[Param], list[RunSpec]]:
    """The parameters and one :class:`RunSpec` per design point.

    Raises
    ------
    SceneError
        The scene file is unreadable or not YAML (a scene that does not validate after a run's
        edits is that run's error, not the sweep's).
    flexmb_core.scene.overrides.OverrideError
        A bad ``--param`` (syntax, a key whose parent the scene lacks, ranges without ``--samples``).
    """
    from ..scene.loader import parse_yaml, read_scene_text

    path = Path(scene_path)
    base = parse_yaml(read_scene_text(path), str(path))     # SceneError naming the file (and line:column)
    if not isinstance(base, dict):
        raise SceneError(str(path), "expected a scene mapping at the top level")
    if every < 1:
        raise FlexmbError(f"--every must be a positive integer, got {every}")
    declared = base.get("outputs")
    if outputs and isinstance(declared, dict) and "include" not in base:
        # a name no run can have is the flag's error, found before a run (each run would fail on it)
        unknown = [o for o in outputs if o.split(".")[0] not in declared]
        if unknown:
            raise FlexmbError(f"--outputs {name_list(unknown)}: {path} declares no such output "
                              f"(it declares {name_list(sorted(declared))})")
    params = [parse_param(p) for p in param_items]
    if not params:
        raise FlexmbError("flexmb sweep needs at least one --param KEY=VALUES")
    points = design(params, samples=samples, distribution=distribution, seed=seed)
    outs = tuple(outputs) if outputs else None
    specs = [make_spec(base, pt, source=str(path), until=until, outputs=outs, every=every) for pt in points]
    return params, specs


def _lost(spec: RunSpec, exc: BaseException) -> dict:
    return {"key": spec.key, "params": spec.params, "until": spec.until, "outputs": list(spec.outputs),
            "every": spec.every, "ok": False, "completed": False, "converged": False,
            "error": f"the cluster lost this run: {type(exc).__name__}: {exc}", "error_kind": "lost"}


def execute(specs: list[RunSpec], out: str | Path, *, scheduler: Any = None, workers: int | None = None,
            retries: int = 2, progress: Callable[[SweepEvent], None] | None = None,
            result: SweepResult | None = None) -> SweepResult:
    """Run every spec not stored under ``out/runs/`` yet (see the module docstring)."""
    out = Path(out)
    res = result or SweepResult(out, [], specs, [None] * len(specs))
    res.rows = [None] * len(specs)
    t0 = time.perf_counter()
    by_key: dict[str, list[int]] = {}
    for i, s in enumerate(specs):
        by_key.setdefault(s.key, []).append(i)
    total, done = len(specs), 0

    def record(key: str, row: dict, stored: bool) -> None:
        nonlocal done
        for i in by_key[key]:
            res.rows[i] = row
            done += 1
            res.failed += not row.get("ok")
            if stored:
                res.cached += 1
            else:
                res.computed += 1
            if progress is not None:
                progress(SweepEvent(done, total, res.computed, res.cached, res.failed, row, specs[i], stored))

    pending: list[RunSpec] = []
    for key, idx in by_key.items():
        row = load_run(out, key)
        if row is None:
            pending.append(specs[idx[0]])
        else:
            record(key, row, True)
    if pending:
        n = min(workers or default_workers(), len(pending))
        with connect(scheduler, n) as client:
            res.scheduler = str(client.scheduler.address)
            res.workers = len(client.nthreads())
            futures = {client.submit(run_one, s, key=f"flexmb-run-{s.key}", pure=False, retries=retries): s
                       for s in pending}
            from dask.distributed import as_completed

            try:
                for fut in as_completed(futures):
                    spec = futures[fut]
                    if fut.status == "finished":
                        row = fut.result()
                        if row.get("error_kind") != "unexpected":
                            save_run(out, row)  # deterministic outcomes only: a bug or a lost run retries
                    else:
                        row = _lost(spec, fut.exception())
                    fut.release()
                    record(spec.key, row, False)
            except KeyboardInterrupt:
                res.interrupted = True
                client.cancel(list(futures))
    res.wall_time_s = time.perf_counter() - t0
    return res


def write_results(res: SweepResult, settings: dict) -> dict[str, str]:
    """``sweep.csv``, ``sweep.parquet``, ``sweep.png`` and ``sweep.json`` under ``res.out``."""
    from .plot import plot_sweep

    res.out.mkdir(parents=True, exist_ok=True)
    records = res.records
    files = {"csv": str(write_csv(res.out / "sweep.csv", records))}
    pq = write_parquet(res.out / "sweep.parquet", records)
    if pq is not None:
        files["parquet"] = str(pq)
    png = plot_sweep(res.out / "sweep.png", records, [p.key for p in res.params])
    if png is not None:
        files["png"] = str(png)
    files["json"] = str(res.out / "sweep.json")
    res.files = files
    summary = {**settings, "runs": len(res.specs), "finished": len(records), "computed": res.computed,
               "stored": res.cached, "failed": res.failed, "interrupted": res.interrupted,
               "wall_time_s": res.wall_time_s, "workers": res.workers, "scheduler": res.scheduler,
               "files": files, "keys": [s.key for s in res.specs]}
    (res.out / "sweep.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return files


def write_scenes(out: str | Path, specs: list[RunSpec]) -> None:
    """Every run's effective scene as ``OUT/scenes/<key>.yaml`` (``flexmb run`` reproduces a row)."""
    d = Path(out) / "scenes"
    d.mkdir(parents=True, exist_ok=True)
    for s in specs:
        p = d / f"{s.key}.yaml"
        if not p.exists():
            p.write_text(s.scene_yaml, encoding="utf-8")


def sweep(scene_path: str | Path, param_items: list[str], *, samples: int | None = None,
          distribution: str = "uniform", seed: int = 0, until: float | None = None,
          outputs: list[str] | None = None, every: int = 1, out: str | Path = DEFAULT_OUT,
          scheduler: Any = None, workers: int | None = None, retries: int = 2,
          progress: Callable[[SweepEvent], None] | None = None) -> SweepResult:
    """Plan, execute and write a sweep (``flexmb sweep``); returns its :class:`SweepResult`."""
    if workers is not None and workers < 1:
        raise FlexmbError(f"--workers must be a positive integer, got {workers}")
    if retries < 0:
        raise FlexmbError(f"--retries must be 0 or more, got {retries}")
    params, specs = plan(scene_path, param_items, samples=samples, distribution=distribution, seed=seed,
                         until=until, outputs=outputs, every=every)
    out = Path(out)
    write_scenes(out, specs)
    res = SweepResult(out, params, specs, [None] * len(specs))
    execute(specs, out, scheduler=scheduler, workers=workers, retries=retries, progress=progress, result=res)
    settings = {"scene": str(scene_path), "params": list(param_items), "samples": samples,
                "distribution": distribution, "seed": seed, "until": until, "outputs": outputs, "every": every}
    write_results(res, settings)
    return res
