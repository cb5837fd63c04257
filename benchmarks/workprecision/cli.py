"""``flexmb bench``: work-precision reports (error against wall time per simulated second).

    flexmb bench                                   # every case, full sweep, peers when installed
    flexmb bench --case b1 --quick --out /tmp/wp   # a small sweep (seconds)
    flexmb bench --case stewart --make-reference   # re-run the stored converged reference first
    flexmb bench --quick --workers 2               # each run a task of a local Dask cluster, 2 at a time

Timing: by default (``--workers 1``) the runs go one after another in this process, each with the
machine's attention to itself — the wall times of the plots. ``--workers N`` runs the sweep's
flexmb runs as Dask tasks on a local cluster of N worker processes (one thread each, at most one
per core: runs that time-share a core would report the sharing as their cost), ``--scheduler
ADDRESS`` on a running cluster. The errors are the same bits either way; the wall times are then
those of N runs going on at once (one per core, but sharing caches, memory bandwidth and any other
load): fine to find the shape of a sweep quickly, not for published numbers — ``workprecision_<case>.json``
records ``workers``, ``scheduler`` and ``timing``. Peers and ``--make-reference`` always run in
this process.

Writes ``workprecision_<case>.csv`` / ``.json`` / ``.png`` per case and ``workprecision.md`` (every case
present in ``--out``) to ``--out`` (default ``docs/benchmarks``). Also runnable without the
``flexmb`` entry point: ``python benchmarks/work_precision.py [flags]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CASE_NAMES = ("b1", "spin_up", "stewart")


def _cases() -> dict:
    from . import b1, spin_up, stewart
    return {"b1": b1, "spin_up": spin_up, "stewart": stewart}


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``flexmb bench`` (importing this module stays cheap: no numba, no flexmb_core)."""
    p.add_argument("--case", choices=CASE_NAMES + ("all",), default="all",
                   help="which benchmark: the cantilever B1, the spin-up maneuver, the Stewart twin, or all")
    p.add_argument("--quick", action="store_true",
                   help="a small sweep (a few Δt of one or two families, shorter runs; seconds per case)")
    p.add_argument("--out", default=str(ROOT / "docs" / "benchmarks"),
                   help="output directory for the CSV, JSON, PNG and markdown files (default: docs/benchmarks)")
    p.add_argument("--no-peers", action="store_true", help="skip the peer codes even when installed")
    p.add_argument("--no-plot", action="store_true", help="skip the PNGs (no matplotlib needed)")
    p.add_argument("--make-reference", action="store_true",
                   help="re-run and store the converged reference of each selected case first "
                        "(benchmarks/reference/<case>.csv; minutes)")
    p.add_argument("--repeats", type=int, default=None,
                   help="at most this many timed repeats per run (default 5, --quick 1); the median counts")
    p.add_argument("--repeat-budget", type=float, default=None, metavar="S",
                   help="repeat a run only while its walls sum to less than S seconds (default 3, --quick 0)")
    p.add_argument("--workers", type=int, default=1, metavar="N",
                   help="run the flexmb runs N at a time as Dask tasks of a local cluster (at most one per core; "
                        "default 1: one after another in this process, the timings of record)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the flexmb runs as tasks of this Dask scheduler (tcp://host:8786; workers started "
                        "from the source checkout)")


def register(verbs, run_parser: argparse.ArgumentParser) -> None:
    """Add ``flexmb bench`` to the ``flexmb`` command (``flexmb.cli`` calls it, as it calls the adapters';
    ``flexmb_core`` never imports ``benchmarks/``)."""
    bn = verbs.add_parser("bench", help="work-precision reports: error against wall time per simulated second "
                                        "(B1, spin-up, Stewart; peers when installed)", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(bn)
    bn.set_defaults(func=run)


def _load() -> str:
    try:
        return f"{os.getloadavg()[0]:.1f}"
    except OSError:
        return "?"


def run(args: argparse.Namespace, log=print) -> int:
    """Run the selected cases; returns the exit code (0; 1 on bad flags or a missing reference)."""
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 5)
    budget = args.repeat_budget if args.repeat_budget is not None else (0.0 if args.quick else 3.0)
    if repeats < 1:
        log(f"flexmb bench: --repeats must be >= 1, got {repeats}", file=sys.stderr)
        return 1
    if budget < 0:
        log(f"flexmb bench: --repeat-budget must be >= 0 s, got {budget}", file=sys.stderr)
        return 1
    workers = getattr(args, "workers", 1)
    scheduler = getattr(args, "scheduler", None)
    if workers is None or workers < 1:
        log(f"flexmb bench: --workers must be a positive integer, got {workers}", file=sys.stderr)
        return 1
    if scheduler is None and workers == 1:
        return _run_cases(args, repeats, budget, log, None)
    from flexmb_core.study.cluster import ClusterError, connect, default_workers

    if scheduler is None and workers > default_workers():
        log(f"flexmb bench: --workers {workers}: this process may use {default_workers()} cores; more runs at "
            "a time than cores would time-share cores and report the sharing as their cost", file=sys.stderr)
        return 1
    try:
        with connect(scheduler, workers, verb="flexmb bench") as client:
            return _run_cases(args, repeats, budget, log, client)
    except ClusterError as exc:
        log(f"flexmb bench: {exc}", file=sys.stderr)
        return 1


def _timing(client) -> tuple[dict, list[str]]:
    """``workers``, ``scheduler``, ``timing`` of the JSON, and notes on how the runs were timed."""
    if client is None:
        return {"workers": 1, "scheduler": "", "timing": "one run at a time in this process"}, []
    from flexmb_core.study.tasks import cluster_facts

    address, n = cluster_facts(client)
    facts = {"workers": n, "scheduler": address,
             "timing": f"up to {n} runs at a time, each a Dask task on a worker process of one thread"}
    notes = [f"flexmb runs timed on Dask: up to {n} at a time (one per worker thread); wall times of runs that "
             "share the machine (caches, memory bandwidth) — rerun with --workers 1 for the timings of record"]
    if any(k > 1 for k in client.nthreads().values()):
        notes.append("some Dask workers have more than one thread: their runs time-shared a process")
    return facts, notes


def _run_cases(args: argparse.Namespace, repeats: int, budget: float, log, client) -> int:
    from benchmarks.stewart_platform import machine_info

    from . import core, report

    out = Path(args.out)
    cases = _cases()
    selected = CASE_NAMES if args.case == "all" else (args.case,)
    facts, timing_notes = _timing(client)
    for name in selected:
        mod = cases[name]
        t0, load_start = time.perf_counter(), _load()
        log(f"== {mod.TITLE}{' (--quick)' if args.quick else ''}", flush=True)
        if args.make_reference:
            log(f"  reference: {mod.FINE.key} ...", flush=True)
            path = mod.make_reference()
            log(f"  wrote {path}", flush=True)
        try:
            header, _, _ = core.read_reference(mod.REFERENCE)
        except FileNotFoundError as exc:
            log(f"flexmb bench: {exc}", file=sys.stderr)
            return 1
        rows = mod.run(args.quick, budget_s=budget, max_repeats=repeats, log=lambda s: log(s, flush=True),
                       client=client)
        notes: list[str] = list(timing_notes)
        if not args.no_peers:
            peer_rows, peer_notes = mod.run_peers(args.quick, repeats=repeats, log=lambda s: log(s, flush=True))
            rows += peer_rows
            notes += peer_notes
            for n in peer_notes:
                log(f"  {n}")
        t_end = mod.until(args.quick) if hasattr(mod, "until") else mod.UNTIL
        meta = {"case": name, "quick": args.quick, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
                "machine": machine_info(), "load_start": load_start, "load_end": _load(),
                "runtime_s": time.perf_counter() - t0, "sim_time_s": t_end, "repeats": repeats,
                "repeat_budget_s": budget, "peers": not args.no_peers, "notes": notes, **facts,
                "reference": {"file": str(mod.REFERENCE.relative_to(core.ROOT)), **header},
                "error_unit": mod.ERROR_UNIT, "error_measure": mod.ERROR_MEASURE}
        report.write_csv(report.csv_path(out, name), rows)
        report.write_json(out / f"workprecision_{name}.json", meta)
        if not args.no_plot:
            png = out / f"workprecision_{name}.png"
            if report.write_png(png, report.read_csv(report.csv_path(out, name)), mod.PANELS, mod.TARGET):
                log(f"  wrote {png}")
            else:
                log("  matplotlib is not installed (extra 'bench'): no PNG")
        log(f"  wrote {report.csv_path(out, name)} ({len(rows)} runs, {meta['runtime_s']:.0f} s)", flush=True)
    md = report.write_markdown(out, cases)
    log(f"wrote {md}")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="flexmb bench", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)
    return run(p.parse_args(argv))
