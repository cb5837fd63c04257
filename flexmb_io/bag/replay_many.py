"""``flexmb replay DIR``: every bag under a directory replayed (each a Dask task) and one table.

DIR is a directory that is not itself a bag (``bags/``). A *bag* under it is a rosbag2 directory
(it holds ``metadata.yaml`` or an ``.mcap`` file; it is not searched further) or an ``.mcap`` file
outside such a directory, at any depth; its name is its path relative to DIR. Each bag is replayed
by :func:`flexmb_io.bag.replay.replay` exactly as ``flexmb replay BAG`` would — the same
``--scene``, ``--override`` and ``--tolerance`` for every bag — as a task of a Dask cluster
(:func:`flexmb_core.study.cluster.connect`: a local cluster of ``--workers`` processes, default
one per core, or ``--scheduler ADDRESS``); with one bag, or ``--workers 1``, the bags are
replayed one after another in this process. A replay's result does not depend on where it runs.

Tolerances: when ``DIR/manifest.yaml`` exists (the format of ``bags/manifest.yaml``: ``bags:
{NAME: {tolerances: {KEY: VALUE}}}``), each bag it lists starts from its entry's tolerances;
``--tolerance`` items apply on top, to every bag; other bags use the defaults. A bag the
manifest lists but DIR does not hold is a failed row (a reference set must not shrink silently).

Exit codes: 0 every bag within tolerance; 3 any regression (a bag beyond tolerance, a failed
replay, a listed bag missing, an unexpected error while replaying one bag); 1 bad input — DIR is
not a directory or holds no bag, an unreadable manifest, a bad ``--tolerance`` — or, when no bag
regressed, a bag that cannot be replayed (not a flexmb recording, its scene does not load: that
bag's row says why, with exit code 1).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from flexmb_core.errors import FlexmbError, excerpt

from . import rosbag2
from .replay import EXIT_BAD_INPUT, EXIT_DEVIATION, EXIT_OK, ReplayError, ReplayReport, replay
from .tolerances import REPORT_UNITS, ToleranceError, parse_tolerances

MANIFEST = "manifest.yaml"


def is_bag_dir(path: Path) -> bool:
    """A rosbag2 directory: ``metadata.yaml`` or an ``.mcap`` file directly inside."""
    path = Path(path)
    return path.is_dir() and ((path / rosbag2.METADATA_FILE).is_file() or any(path.glob("*.mcap")))


def find_bags(root: Path) -> list[Path]:
    """Every bag under ``root`` (see the module docstring), sorted by relative path; hidden
    directories are skipped."""
    root = Path(root)
    found: list[Path] = []
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        if d != root and is_bag_dir(d):
            found.append(d)
            dirnames[:] = []
            continue
        dirnames[:] = sorted(n for n in dirnames if not n.startswith("."))
        found += [d / f for f in filenames if f.endswith(".mcap")]
    return sorted(found, key=lambda p: p.relative_to(root).as_posix())


def manifest_bags(path: Path) -> dict:
    """The ``bags`` mapping (name → entry) of the manifest file ``path`` (``bags/manifest.yaml``'s
    format), for the replay of a directory and ``flexmb bag regenerate`` alike.

    Raises
    ------
    ReplayError
        When the file cannot be read, is not YAML or has no ``bags`` mapping.
    """
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ReplayError(f"{path}: cannot read the manifest ({excerpt(str(exc), 200)})") from None
    bags = data.get("bags") if isinstance(data, dict) else None
    if not isinstance(bags, dict):
        raise ReplayError(f"{path}: expected a mapping 'bags: {{NAME: {{tolerances: {{KEY: VALUE}}}}}}', "
                          f"got {excerpt(repr(data), 80)}")
    return bags


def manifest_tolerances(root: Path) -> dict[str, dict]:
    """Bag name → tolerances mapping of ``root/manifest.yaml`` ({} without a manifest).

    Raises
    ------
    ReplayError
        When the manifest is not YAML or not ``bags: {NAME: {tolerances: {...}}}``.
    """
    path = Path(root) / MANIFEST
    if not path.exists():
        return {}
    bags = manifest_bags(path)        # not a file (a directory of that name): "cannot read the manifest"
    out = {}
    for name, entry in bags.items():
        entry = {} if entry is None else entry
        tol = entry.get("tolerances") if isinstance(entry, dict) else None
        if not isinstance(entry, dict) or not isinstance(tol, (dict, type(None))):
            raise ReplayError(f"{path}:bags.{name}: expected a mapping with an optional 'tolerances' mapping, "
                              f"got {excerpt(repr(entry), 80)}")
        out[str(name)] = dict(tol or {})
    return out


@dataclass(frozen=True)
class BagJob:
    """One bag's replay (picklable: what a Dask task receives)."""

    name: str                          # path relative to DIR
    path: str
    tolerances: dict                   # effective tolerances (every key)
    tolerances_from: str               # "manifest" or "defaults" (before --tolerance items)
    scene_path: str | None = None
    overrides: tuple[str, ...] = ()


@dataclass
class BagResult:
    """One row of the table: the bag, its exit code (0, 1, 3) and its replay report (None when it
    could not be replayed or is missing)."""

    name: str
    path: str
    exit_code: int
    tolerances: dict
    tolerances_from: str
    error: str = ""
    report: ReplayReport | None = None

    @property
    def ok(self) -> bool:
        return self.exit_code == EXIT_OK

    def worst(self) -> dict | None:
        """The field closest to (or furthest beyond) its limit: deviation / limit largest."""
        if self.report is None or not self.report.fields:
            return None
        tol = self.report.tolerances

        def ratio(f) -> float:
            lim = f.limit(tol)
            return f.worst / lim if lim > 0 else (math.inf if f.worst > 0 else 0.0)
        f = max(self.report.fields, key=ratio)
        return {"topic": f.topic, "field": f.field, "kind": f.kind, "worst": f.worst, "limit": f.limit(tol),
                "unit": REPORT_UNITS[f.kind], "t": f.t, "element": f.element, "ok": f.ok(tol),
                "identical": all(x.identical for x in self.report.fields)}

    def summary(self) -> str:
        """The 'worst field' cell: the worst field, or why the bag failed."""
        if self.error:
            return self.error
        w = self.worst()
        rep = self.report
        why = ([f"{len(rep.mismatches)} structural mismatch(es)"] if rep.mismatches else []) + \
              (["replay failed"] if rep.failure else []) + \
              ([f"{rep.samples_unmatched} recorded outputs not reproduced"] if rep.samples_unmatched else [])
        if w is None:
            return "; ".join(why) or "nothing compared"
        if w["identical"] and not why:
            return "every field bit-identical"
        text = f"{w['topic']} {w['field']} {w['worst']:.3e} / {w['limit']:.3e} {w['unit']}"
        return "; ".join([text] + why)


def replay_one(job: BagJob) -> BagResult:
    """Replay one bag (the Dask task). Never raises: bad input is exit code 1, anything unexpected 3."""
    res = BagResult(job.name, job.path, EXIT_BAD_INPUT, job.tolerances, job.tolerances_from)
    try:
        res.report = replay(job.path, tolerances=job.tolerances, scene_path=job.scene_path,
                            overrides=list(job.overrides) or None)
    except FlexmbError as exc:                 # ReplayError, SceneError, BagError, OverrideError
        res.error = excerpt(str(exc), 300)[1:-1]
        return res
    except Exception as exc:  # noqa: BLE001 - one bag's crash is its row, the others still replay
        res.exit_code, res.error = EXIT_DEVIATION, f"unexpected {type(exc).__name__}: {excerpt(str(exc), 300)[1:-1]}"
        return res
    res.exit_code = res.report.exit_code
    return res


@dataclass
class DirReport:
    """What ``flexmb replay DIR`` found: one :class:`BagResult` per bag, in name order."""

    root: str
    results: list[BagResult]
    workers: int = 1
    scheduler: str = ""
    wall_time_s: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(r.ok for r in self.results)

    @property
    def exit_code(self) -> int:
        codes = {r.exit_code for r in self.results}
        return EXIT_OK if codes <= {EXIT_OK} else (EXIT_DEVIATION if EXIT_DEVIATION in codes else EXIT_BAD_INPUT)

    def as_dict(self) -> dict:
        return {"dir": self.root, "ok": self.ok, "exit_code": self.exit_code, "workers": self.workers,
                "scheduler": self.scheduler, "wall_time_s": self.wall_time_s, "notes": self.notes,
                "bags": [{"bag": r.name, "path": r.path, "ok": r.ok, "exit_code": r.exit_code, "worst": r.worst(),
                          "summary": r.summary(), "tolerances": r.tolerances, "tolerances_from": r.tolerances_from,
                          "error": r.error, "report": r.report.as_dict() if r.report is not None else None}
                         for r in self.results]}

    def format(self) -> str:
        """The table: bag, ok, worst field (deviation / limit, or why it failed), exit code."""
        where = (f"on Dask ({self.workers} workers, scheduler {self.scheduler})" if self.scheduler
                 else "in this process")
        n_ok = sum(r.ok for r in self.results)
        n_reg = sum(r.exit_code == EXIT_DEVIATION for r in self.results)
        lines = [f"replay of {len(self.results)} bags under {self.root} {where}: {n_ok} ok, {n_reg} regressed, "
                 f"{len(self.results) - n_ok - n_reg} could not be replayed; {self.wall_time_s:.1f} s"]
        w = max([len(r.name) for r in self.results] + [3])
        cells = [r.summary() + ("" if r.tolerances_from == "manifest" else " [default tolerances]")
                 for r in self.results]
        c = max([len(x) for x in cells] + [43])
        lines.append(f"  {'bag':{w}s}  {'ok':3s} {'worst field (deviation / limit) or failure':{c}s}  exit")
        for r, cell in zip(self.results, cells):
            lines.append(f"  {r.name:{w}s}  {'ok' if r.ok else 'NO':3s} {cell:{c}s}  {r.exit_code}")
        lines += [f"  note: {n}" for n in self.notes]
        code = self.exit_code
        if code == EXIT_OK:
            lines.append("result: every bag within tolerance (exit 0)")
        else:
            bad = [r.name for r in self.results if not r.ok]
            lines.append(("result: REGRESSION in " if code == EXIT_DEVIATION else "result: could not replay ")
                         + ", ".join(bad) + f" (exit {code})")
        return "\n".join(lines)


def plan(root: Path, *, tolerances: list[str] | None = None, scene_path: str | None = None,
         overrides: list[str] | None = None) -> tuple[list[BagJob], list[BagResult]]:
    """The jobs for every bag under ``root`` and the failed rows of listed-but-missing bags.

    Raises
    ------
    ReplayError
        ``root`` is not a directory or holds no bag; a bad manifest or ``--tolerance``.
    """
    root = Path(root)
    if not root.is_dir():
        raise ReplayError(f"{root}: not a directory (expected a bag, or a directory of bags)")
    listed = manifest_tolerances(root)
    bags = find_bags(root)
    names = [b.relative_to(root).as_posix() for b in bags]
    if not bags:
        raise ReplayError(f"{root}: no bags under this directory (expected rosbag2 directories with metadata.yaml "
                          "and an .mcap file, or .mcap files)")
    jobs = []
    for name, path in zip(names, bags):
        try:
            tol = parse_tolerances(tolerances, listed.get(name))
        except ToleranceError as exc:
            where = f"{root / MANIFEST}:bags.{name}.tolerances: " if name in listed else ""
            raise ReplayError(f"{where}{exc}") from None
        jobs.append(BagJob(name, str(path), tol, "manifest" if name in listed else "defaults", scene_path,
                           tuple(overrides or ())))
    missing = [BagResult(n, str(root / n), EXIT_DEVIATION, {}, "manifest",
                         error=f"listed in {MANIFEST}, not found under {root}")
               for n in sorted(set(listed) - set(names))]
    return jobs, missing


def replay_dir(root, *, tolerances: list[str] | None = None, scene_path: str | None = None,
               overrides: list[str] | None = None, scheduler=None, workers: int | None = None,
               on_result=None) -> DirReport:
    """Replay every bag under ``root`` (see the module docstring); ``on_result(result)`` as each
    bag finishes. Raises :class:`ReplayError` on bad input (exit code 1)."""
    import importlib.util

    from flexmb_core.study.cluster import connect, default_workers

    if workers is not None and workers < 1:
        raise ReplayError(f"--workers must be a positive integer, got {workers}")
    jobs, missing = plan(root, tolerances=tolerances, scene_path=scene_path, overrides=overrides)
    t0 = time.perf_counter()
    report = DirReport(str(root), [])
    n = min(workers or default_workers(), len(jobs))
    if not scheduler and (n == 1 or importlib.util.find_spec("distributed") is None):
        if n > 1:
            report.notes.append("Dask is not installed (extra [cluster]): the bags were replayed one after another")
        results = []
        for j in jobs:
            results.append(replay_one(j))
            if on_result is not None:
                on_result(results[-1])
    else:
        from flexmb_core.study.tasks import cluster_facts, run_all

        with connect(scheduler, n, verb="flexmb replay DIR") as client:
            report.scheduler, report.workers = cluster_facts(client)
            results = run_all(client, replay_one, jobs, name="flexmb-replay",
                              on_result=None if on_result is None else (lambda i, r: on_result(r)))
    report.results = sorted(results + missing, key=lambda r: r.name)
    report.wall_time_s = time.perf_counter() - t0
    return report
