"""flexmb — flexible digital twin of actuated spatial mechanisms (positional FEM).

Every verb below has its own --help (flexmb VERB --help); the README's command table shows them
all with their flags.

Exit codes: 0 success, 1 bad input (scene, flags), 2 a step did not converge, 3 a result short of
what was asked (replay, replay-live: an output beyond tolerance; calibrate: the fit did not converge;
tune: no candidate within tolerance; sweep: some runs failed), 130 interrupted (SIGINT/SIGTERM).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
import time
import warnings
from pathlib import Path

from .errors import ConvergenceError, FlexmbError, SceneError, path_excerpt, thousands, writable_dir, writable_file


def _env_defaults() -> None:
    # Keep BLAS single-threaded (two threads on two cores slow small solves down) and give numba
    # a writable cache even when the package is installed read-only.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("NUMBA_CACHE_DIR", str(Path.home() / ".cache" / "flexmb" / "numba"))


# Errors of loading or compiling a scene that are not FlexmbError: reported in one line, not as a
# traceback (FLEXMB_DEBUG=1 shows it). Caught around scene loading only, never around the time loop.
_STRAY = (ValueError, TypeError, KeyError, IndexError, ArithmeticError, RecursionError, MemoryError,
          UnicodeError)
MESSAGE_CHARS = 1500          # an error message printed by main is at most this long
MAX_TABLE_ROWS = 10_000_000  # rows of `commands` at most (0.7 GB of CSV; 20 s at 2 µs)


def _load(path: str, overrides: dict | None = None, limits=None):
    """Load and compile a scene; every failure is a :class:`SceneError` naming the file."""
    from .model.compile import compile_scene
    from .scene import load_scene

    try:
        scene = load_scene(path, overrides, limits=limits)
        return scene, compile_scene(scene, limits)
    except FlexmbError:
        raise
    except _STRAY as exc:
        if os.environ.get("FLEXMB_DEBUG"):
            raise
        raise SceneError(str(path), _stray_message(exc)) from None


def _stray_message(exc: BaseException) -> str:
    from .errors import excerpt

    if isinstance(exc, MemoryError):
        return "out of memory while loading the scene; lower its size (elements, tables) or its limits"
    text = excerpt(str(exc), 300)[1:-1] if str(exc) else ""
    return (f"the scene could not be compiled: {type(exc).__name__}: {text} (flexmb did not expect this "
            "input; FLEXMB_DEBUG=1 shows the traceback — please report it)")


def _limits(args: argparse.Namespace):
    from .scene.limits import Limits

    given = {f: getattr(args, f) for f in ("max_elements", "max_dofs", "max_yaml_nodes", "max_file_bytes")
             if getattr(args, f, None) is not None}
    return Limits(**given) if given else None


def add_limit_flags(p: argparse.ArgumentParser) -> None:
    """``--max-elements`` etc.: the size limits of :class:`~flexmb_core.scene.limits.Limits`."""
    from .scene.limits import DEFAULT_LIMITS as d

    g = p.add_argument_group("scene size limits", "checked before any per-element work; raise them for big scenes")
    g.add_argument("--max-elements", type=_positive_int, metavar="N",
                   help=f"most frame, bar and shell elements in all (default {d.max_elements})")
    g.add_argument("--max-dofs", type=_positive_int, metavar="N",
                   help=f"most DOFs before joints merge shared ones (default {d.max_dofs})")
    g.add_argument("--max-yaml-nodes", type=_positive_int, metavar="N",
                   help=f"most YAML values after alias expansion (default {d.max_yaml_nodes})")
    g.add_argument("--max-file-bytes", type=_positive_int, metavar="N",
                   help=f"largest scene file (default {d.max_file_bytes})")


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text[:40]!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def cmd_check(args: argparse.Namespace) -> int:
    _, model = _load(args.scene, limits=_limits(args))
    summary = model.summary()
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"scene {summary['scene']}: OK")
    for k in ("dofs", "free_dofs", "prescribed_dofs", "nodes", "members", "rigid_corners", "tangent_nonzeros"):
        print(f"  {k:18s} {summary[k]}")
    print(f"  {'mass':18s} {summary['mass_kg']:.6g} kg")
    print(f"  {'elements':18s} " + ", ".join(f"{k}: {v}" for k, v in summary["elements"].items()))
    if summary["actuators"]:
        print(f"  {'actuators':18s} {', '.join(summary['actuators'])}")
    for g in summary["frame_groups"]:
        print(f"  {'frame group':18s} {g}")
    return 0


class _Progress:
    """A plain stderr progress bar (no dependency), redrawn at most 5 times a second."""

    def __init__(self, until: float, enabled: bool):
        self.until = until
        self.enabled = enabled and sys.stderr.isatty()
        self.last = 0.0

    def __call__(self, sim, res) -> None:
        now = time.perf_counter()
        if not self.enabled or (now - self.last < 0.2 and sim.state.t < self.until):
            return
        self.last = now
        frac = min(sim.state.t / self.until, 1.0)
        bar = "#" * int(30 * frac)
        sys.stderr.write(f"\r[{bar:30s}] t = {sim.state.t:8.4f} s  iters {res.iterations:2d}")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")


class _StopOnSignal:
    """SIGINT and SIGTERM during a run: the step under way ends, then the run stops as interrupted
    (``check`` raises KeyboardInterrupt between steps), so the JSON, the summary and every hook's
    recording describe a whole state — Python's default SIGINT would interrupt a step half way and
    SIGTERM's would end the process with nothing written. A second signal interrupts at once (a step
    that takes minutes must not hold Ctrl-C off). Only the main thread installs handlers; the former
    ones come back on exit."""

    def __init__(self):
        self.signum: int | None = None
        self._old: dict[int, object] = {}

    def __enter__(self) -> "_StopOnSignal":
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._note)
        return self

    def _note(self, signum, frame) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt(f"signal {signum} again")
        self.signum = signum

    def check(self) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt(f"signal {self.signum}")

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old.clear()


def cmd_run(args: argparse.Namespace) -> int:
    from .simulator import Simulator
    from .tracking import PoseTracker

    overrides = {"dt": args.dt, "until": args.until, "integrator": args.integrator}
    if args.json:
        writable_file(args.json, "--json", inputs=(args.scene,))   # before the run: no work lost to a bad path
    scene, model = _load(args.scene, overrides, _limits(args))
    spec = scene.solver
    sim = Simulator(model)
    path = None
    if spec.analysis == "static" and spec.control != "load":
        from .integrators.path_following import PathFollower
        path = PathFollower(sim)              # SceneError (exit 1) for loads it cannot scale
    warm = sim.warmup()
    error = ""
    if path is None:
        try:
            sim.initialize()
        except ConvergenceError as exc:     # the initial static equilibrium: exit 2 and the JSON, as a step
            error = str(exc)
    until = spec.until
    progress = _Progress(until if path is None else spec.max_steps, not args.quiet)
    tracker = PoseTracker(model)

    # Adapters (MCAP recorder, rerun logger) attach here: hooks with start(sim), step(sim, res)
    # and close(sim, summary). The core never imports them.
    hooks = [h(args, scene, model) for h in getattr(args, "hook_factories", ())] if not error else []
    hooks = [h for h in hooks if h is not None]

    stop = _StopOnSignal()

    def on_step(s, res):
        tracker.update(s.state.t, s.state.q)
        progress(s, res)
        for h in hooks:
            h.step(s, res)
        stop.check()

    with stop:        # until every hook has closed its recording
        try:
            if path is not None:
                path.initialize()
            for h in hooks:
                h.start(sim)
            if error:
                pass                          # no state to start from: nothing to run or record
            elif path is None:
                sim.run(until, callback=on_step)
            else:
                path.run(callback=on_step)
        except ConvergenceError as exc:
            error = str(exc)
        except KeyboardInterrupt:
            # SIGINT/SIGTERM (_StopOnSignal): stop stepping but close every hook (recordings keep all
            # they got) and report
            error = f"interrupted at t = {sim.state.t:.6g} s"
        finally:
            progress.close()
        summary = sim.summary()
        summary.update({"scene": scene.name, "scene_file": str(args.scene), "analysis": spec.analysis})
        summary.update(_run_keys(spec, sim, path, error))
        error = summary["error"]
        summary.update({"jit_warmup_s": warm, "completed": not error, "outputs": sim.outputs()})
        tracking = tracker.summary()
        if tracking:
            summary["tracking"] = tracking
        for h in hooks:
            h.close(sim, summary)
    text = json.dumps(summary, indent=2, allow_nan=True)
    unwritten = ""
    if args.json:
        try:
            Path(args.json).write_text(text + "\n")
        except OSError as exc:        # a full disk: the summary is printed instead, not lost
            unwritten = f"--json {path_excerpt(Path(args.json))}: cannot write the summary ({exc.strerror or exc})"
    if not args.quiet or unwritten:
        _print_run(scene, summary, warm, tracker)
    if unwritten:
        print(_bounded(f"flexmb run: {unwritten}"), file=sys.stderr)
    if error:
        print(f"flexmb run: {error}", file=sys.stderr)
        return 130 if error.startswith("interrupted") else 2
    return 1 if unwritten else 0


def _run_keys(spec, sim, path, error: str) -> dict:
    """The keys of ``flexmb run --json`` that depend on the analysis: dynamics names its integrator
    and Δt; statics its control and what it found on the path (limit points, bifurcations,
    snap-throughs — a snap-through the scene does not allow is the run's error)."""
    if spec.analysis != "static":
        return {"dt": spec.dt, "until": spec.until, "integrator": spec.integrator, "error": error}
    if path is not None:
        keys = path.report()
        keys["error"] = error
        return keys
    monitor = sim._static.snap if sim._static is not None else None
    snap = monitor.events if monitor is not None else []
    bifurcations = monitor.bifurcations if monitor is not None else []
    if snap and not spec.allow_snap_through and not error:
        first = snap[0]
        error = (f"snap-through at load step {first['step']} (t = {first['t']:.6g}): {first['kind']} "
                 f"(negative pivots {first['negative_pivots'][0]} → {first['negative_pivots'][1]}, the step "
                 f"moved {first['jump_ratio']:.3g}× its tangent prediction); load stepping cannot follow "
                 f"the path past a critical point: trace it with solver.control: arc_length, or allow "
                 f"the snap with solver.allow_snap_through: true")
    return {"control": "load", "dt": spec.dt, "until": spec.until, "snap_through": snap,
            "bifurcations": bifurcations, "error": error}


def _print_run(scene, summary: dict, warm: float, tracker) -> None:
    print(f"{scene.name}: {summary['steps']} steps to t = {summary['sim_time_s']:.6g} s in "
          f"{summary['wall_time_s']:.3f} s (RTF {summary['rtf']:.3g}, {summary['steps_per_s']:.0f} steps/s, "
          f"JIT warm-up {warm:.2f} s); Newton mean {summary['newton_iterations_mean']:.2f}, "
          f"max {summary['newton_iterations_max']}; unconverged {summary['unconverged_steps']}")
    if "limit_points" in summary:
        print(f"  load factor {summary['load_factor']:.6g}, {len(summary['limit_points'])} limit point(s), "
              f"{len(summary['bifurcations'])} bifurcation(s)")
        for c in summary["limit_points"] + summary["bifurcations"]:
            print(f"    {c['kind']} at increment {c['step']}: load factor {c['load_factor']:.6g}, "
                  f"displacement {c['displacement']}")
    for s in summary.get("snap_through", []):
        print(f"  snap-through at load step {s['step']} (t = {s['t']:.6g}): {s['kind']}, "
              f"displacement {s['displacement_before']} → {s['displacement']}")
    if "limit_points" not in summary:
        for b in summary.get("bifurcations", []):
            print(f"  {b['kind']} (a bifurcation passed without a jump, the run stays on the fundamental branch) "
                  f"at load step {b['step']} (t = {b['t']:.6g}): negative pivots {b['negative_pivots'][0]} → "
                  f"{b['negative_pivots'][1]}")
    for k, v in summary["outputs"].items():
        print(f"  {k}: {_brief(v)}")
    tr = summary.get("tracking")
    if tr:
        print(f"  tracking of '{tr['output']}' vs the commanded pose: max position error "
              f"{tr['max_position_error_m']:.3e} m (t = {tr['t_of_max_position_error_s']:.3f} s), "
              f"rms {tr['rms_position_error_m']:.3e} m, max orientation error {tr['max_orientation_error_rad']:.3e} rad")


def _brief(value, limit: int = 6) -> str:
    """A printable output value: long lists (shapes) show their length and ends; the JSON summary
    keeps them whole."""
    if isinstance(value, list) and len(value) > limit:
        return f"[{len(value)} entries: {value[0]}, …, {value[-1]}]"
    return str(value)


def cmd_commands(args: argparse.Namespace) -> int:
    import numpy as np

    from .mechanisms import stewart

    steps = args.until / args.dt            # inf for --until 1e308: checked before any int()
    if not steps + 1 <= MAX_TABLE_ROWS:
        rows = thousands(int(round(steps)) + 1) if steps < 1e15 else f"{steps:.3g}"
        raise FlexmbError(f"--dt {args.dt:g}: {rows} rows over --until {args.until:g} s; at most "
                          f"{thousands(MAX_TABLE_ROWS)} (--dt ≥ {args.until / (MAX_TABLE_ROWS - 1):.3g} s)")
    n = int(round(steps)) + 1
    t = np.linspace(0.0, args.until, n)
    try:
        lengths, rates = stewart.appendix_leg_lengths(t, start=args.start, blend_time=args.blend_time,
                                                      switch_blend=args.switch_blend,
                                                      blend_continuity=args.blend_continuity)
    except ValueError as exc:          # the law's own checks of --until, --blend-time, --switch-blend
        text = str(exc).replace("blend_time", "--blend-time").replace("switch_blend", "--switch-blend")
        raise FlexmbError(text.replace("got times in", "--until asks for times in")) from None
    try:
        stewart.write_command_table(args.out, t, lengths, rates)
    except OSError as exc:
        raise FlexmbError(f"--out {args.out}: cannot write the table ({exc.strerror or exc})") from None
    print(f"wrote {n} rows × 6 legs ({args.start} start) to {args.out}")
    return 0


def cmd_tune(args: argparse.Namespace) -> int:
    import yaml

    from .scene.loader import parse_yaml, read_scene_text
    from .tune import held_outputs, report_markdown, tune

    path = Path(args.scene)
    _load(args.scene)                                   # validate first: errors name file:key
    data = parse_yaml(read_scene_text(path), str(path))
    if not (math.isfinite(args.tol) and args.tol > 0):
        print(f"flexmb tune: --tol must be a positive number, got {args.tol}", file=sys.stderr)
        return 1
    out = writable_dir(args.out or "build/tune", "--out")    # before the trials: none lost to a bad path
    if args.workers is not None and args.workers < 1:
        print(f"flexmb tune: --workers must be a positive integer, got {args.workers}", file=sys.stderr)
        return 1
    until = args.until if args.until is not None else float(data.get("solver", {}).get("until", 1.0))
    held = tuple(x for x in (args.outputs or "").split(",") if x) or None
    held_outputs(data, str(path), held)                 # bad --outputs before any cluster starts

    def progress(trial):
        if not args.quiet:
            state = "ok " if trial.ok else ("ERR" if trial.message else "   ")
            how = {"parallel": " (parallel screen)", "re-timed": " (re-timed alone)"}.get(trial.timing, "")
            print(f"  [{state}] {trial.label}: {trial.steps_per_s:8.0f} steps/s{how}, max error "
                  f"{trial.max_error:.2e}", flush=True)

    result = _tune_where(args, lambda ev: tune(data, args.tol, until, source=str(path), progress=progress,
                                                outputs=held, evaluator=ev))
    stem = path.stem
    tuned = out / f"{stem}_tuned.yaml"
    best = result.best
    header = (f"# Tuned from {path} by `flexmb tune --tol {args.tol:g} --until {result.until:g}`:\n"
              f"# {best.label}; {best.steps_per_s:.0f} steps/s, largest output error {best.max_error:.2e} against\n"
              f"# the refined reference (table: {stem}_tune.md). Comments of the original are not carried over.\n")
    tuned.write_text(header + yaml.safe_dump(best.scene, sort_keys=False, allow_unicode=True))
    (out / f"{stem}_tune.md").write_text(report_markdown(result, data.get("name", stem)))
    (out / f"{stem}_tune.json").write_text(json.dumps({
        "scene": str(path), "tolerance": args.tol, "until": result.until, "tuned_scene": str(tuned),
        "reference_wall_per_sim_s": result.reference_wall_per_sim_s,
        "chosen": best.label, "within_tolerance": best.ok, "workers": result.workers, "scheduler": result.scheduler,
        "trials": [{"label": t.label, "ok": t.ok, "steps_per_s": t.steps_per_s, "wall_per_sim_s": t.wall_per_sim_s,
                    "errors": t.errors, "message": t.message, "timing": t.timing,
                    "screen_wall_per_sim_s": t.screen_wall_per_sim_s, "screen_cpu_per_sim_s": t.screen_cpu_per_sim_s}
                   for t in result.trials]}, indent=1))
    if not args.quiet:
        print(f"chosen: {best.label} ({best.steps_per_s:.0f} steps/s, "
              f"{result.baseline.wall_per_sim_s / best.wall_per_sim_s:.2f}× the scene as declared, "
              f"largest error {best.max_error:.2e}); wrote {tuned} and {stem}_tune.md")
    return 0 if best.ok else 3


def _tune_where(args: argparse.Namespace, search):
    """``search(evaluator)`` on Dask (``--scheduler``, or a local cluster of ``--workers`` processes,
    default one per core) or, with ``--workers 1`` / one core / Dask not installed, in this process."""
    import importlib.util

    from .study.cluster import connect, default_workers
    from .tune import InProcess, OnDask

    if not args.scheduler and (args.workers or default_workers()) == 1:
        return search(InProcess())
    if not args.scheduler and importlib.util.find_spec("distributed") is None:
        if not args.quiet:
            print("flexmb tune: Dask is not installed (extra [cluster]): candidates run one after another "
                  "in this process", file=sys.stderr)
        return search(InProcess())
    with connect(args.scheduler, args.workers, verb="flexmb tune") as client:
        return search(OnDask(client))


def cmd_sweep(args: argparse.Namespace) -> int:
    from .study.design import MAX_RUNS
    from .study.progress import ProgressBar
    from .study.sweep import DEFAULT_OUT, sweep

    params = [x for group in (args.param or []) for x in group]
    outputs = [x for x in (args.outputs or "").split(",") if x] or None
    if args.samples is not None and not 1 <= args.samples <= MAX_RUNS:
        raise FlexmbError(f"--samples: expected 1 to {MAX_RUNS} runs, got {args.samples}")
    if args.seed < 0:
        raise FlexmbError(f"--seed: expected a non-negative integer, got {args.seed}")
    writable_dir(args.out or DEFAULT_OUT, "--out")
    res = sweep(args.scene, params, samples=args.samples, distribution=args.distribution, seed=args.seed,
                until=args.until, outputs=outputs, every=args.every, out=args.out, scheduler=args.scheduler,
                workers=args.workers, retries=args.retries,
                progress=None if args.quiet else ProgressBar(sys.stderr))
    if not args.quiet:
        print(f"{len(res.specs)} runs: {res.computed} computed, {res.cached} stored already, {res.failed} failed "
              f"({res.wall_time_s:.2f} s on {res.workers or 0} workers); table {res.files.get('csv')}")
        for row in [r for r in res.rows if r is not None and not r.get("ok")][:5]:
            print(f"  failed {row['params']}: {row['error']}")
    if res.interrupted:
        print("flexmb sweep: interrupted; the finished runs are stored, run the command again to resume",
              file=sys.stderr)
        return 130
    return 3 if res.failed else 0


def _sweep_help() -> str:
    return """A parameter study of a scene; every run is a task on Dask distributed (extra [cluster]).

--param KEY=VALUES (repeatable): KEY is a scene key path, as `flexmb replay --override`
(materials.steel.E, point_masses.payload_a.mass, solver.dt, supports.0.type). VALUES is a list
a,b,c (the list parameters are crossed: full factorial, the first --param varying slowest) or a
range LO:HI, sampled with --samples N points of a seeded Latin hypercube over all range parameters
(--distribution uniform | loguniform | normal: mean (LO+HI)/2, sigma (HI-LO)/4, truncated to
[LO, HI]); integer bounds (2:8) give integers. List and range parameters together: each list
combination gets the same N samples.

Each run loads the scene with its values, compiles, warms up (numba cache shared on disk through
NUMBA_CACHE_DIR), runs to --until and returns one row: the parameters, the `flexmb run --json`
metrics, the max/min/RMS over time and final value of every chosen output part, the wall time and
the convergence flags. A failed run is a row with its error. Rows are stored as OUT/runs/<sha256
of the effective scene, until, outputs>.json as they finish: running the command again computes
only what is missing (a killed sweep resumes). A worker that dies mid-run loses nothing: the
scheduler runs the task again elsewhere.

Writes OUT/sweep.csv, sweep.parquet (with pyarrow), sweep.png (with matplotlib), sweep.json and
scenes/<key>.yaml (each run's scene: `flexmb run` reproduces its row).
Exit codes: 0 every run completed, 3 some runs failed (their rows say why), 1 bad input, 130 interrupted.
"""


class _Parser(argparse.ArgumentParser):
    """argparse with the CLI's exit code for bad input (1, README "Exit codes"); argparse's own is
    2, which ``flexmb run`` uses for a step that did not converge. Subcommand parsers are of the
    same class."""

    def error(self, message: str):
        self.print_usage(sys.stderr)
        self.exit(1, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="flexmb", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="verb", required=True)

    c = sub.add_parser("check", help="validate a scene and print the model summary")
    c.add_argument("scene")
    c.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_limit_flags(c)
    c.set_defaults(func=cmd_check)

    r = sub.add_parser("run", help="offline simulation with a JSON summary")
    r.add_argument("scene")
    r.add_argument("--until", type=float, help="end time (s); default: the scene's solver.until")
    r.add_argument("--dt", type=float, help="time step (s); default: the scene's solver.dt")
    r.add_argument("--integrator", choices=("newmark", "generalized_alpha", "chung_hulbert"))
    r.add_argument("--json", metavar="OUT", help="write the run summary (JSON) here")
    r.add_argument("--quiet", action="store_true", help="no progress bar, no console summary")
    add_limit_flags(r)
    r.set_defaults(func=cmd_run, hook_factories=[])

    cm = sub.add_parser("commands", help="generate actuator command tables")
    cm.add_argument("mechanism", choices=("stewart",))
    cm.add_argument("--out", required=True, help="CSV file: t, leg1..leg6 (m), leg1_rate.. (m/s)")
    cm.add_argument("--dt", type=float, default=1e-3, help="sample period (s)")
    cm.add_argument("--until", type=float, default=20.0, help="end time (s), at most 20")
    cm.add_argument("--start", choices=("exact", "blended"), default="blended",
                    help="exact appendix law (non-zero initial velocity) or C²-blended start")
    cm.add_argument("--blend-time", type=float, default=1.0, help="blend duration (s)")
    cm.add_argument("--switch-blend", type=float, default=0.0,
                    help="blend of the t = 10 s branch switch (s); 0: the exact law's rate jump")
    cm.add_argument("--blend-continuity", type=int, choices=(2, 3, 4), default=2,
                    help="continuity of the blends: C² (quintic), C³, C⁴ (nonic)")
    cm.set_defaults(func=cmd_commands)

    tn = sub.add_parser("tune", help="cheapest fidelity whose outputs stay within a tolerance of a converged "
                                     "reference (model only what a scene needs)")
    tn.add_argument("scene")
    tn.add_argument("--tol", type=float, required=True,
                    help="largest output error: m for positions, rad for angles, relative for forces and energy")
    tn.add_argument("--until", type=float, help="horizon of every trial (s); default: the scene's solver.until")
    tn.add_argument("--out", help="directory for SCENE_tuned.yaml, SCENE_tune.md/.json (default build/tune)")
    tn.add_argument("--outputs", metavar="A,B,..",
                    help="outputs held to --tol (default: the kinematic ones; forces and energy are reported)")
    tn.add_argument("--scheduler", metavar="ADDRESS",
                    help="a running Dask scheduler (tcp://host:8786); default: a local cluster")
    tn.add_argument("--workers", type=int, metavar="N",
                    help="worker processes of the local cluster (default: one per core; 1: no Dask, the "
                         "candidates run one after another in this process)")
    tn.add_argument("--quiet", action="store_true")
    tn.set_defaults(func=cmd_tune)

    sw = sub.add_parser("sweep", help="parameter study over scene keys, each run a task on Dask distributed "
                                      "(extra [cluster]); a table, plots, resumable",
                        description=_sweep_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    sw.add_argument("scene")
    sw.add_argument("--param", metavar="KEY=VALUES", nargs="+", action="append", required=True,
                    help="scene key path (as replay --override) and a list a,b,c or a range LO:HI")
    sw.add_argument("--samples", type=int, help="Latin hypercube samples over the range parameters")
    sw.add_argument("--distribution", choices=("uniform", "loguniform", "normal"), default="uniform",
                    help="of the range parameters (normal: mean (LO+HI)/2, σ = (HI-LO)/4, truncated)")
    sw.add_argument("--seed", type=int, default=0, help="seed of the Latin hypercube")
    sw.add_argument("--until", type=float, help="end time of every run (s); default: the scene's solver.until")
    sw.add_argument("--outputs", metavar="A,B,..",
                    help="outputs (or parts: platform.position) whose max/min/RMS go in the table; "
                         "default: every declared output but whole shapes")
    sw.add_argument("--every", type=int, default=1, help="sample the outputs every K steps")
    sw.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler (tcp://host:8786); "
                                                            "default: a local cluster")
    sw.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per core)")
    sw.add_argument("--retries", type=int, default=2, help="re-runs of a task that raised on a worker")
    sw.add_argument("--out", default="build/sweep", help="directory: runs/, scenes/, sweep.csv/.parquet/.png/.json")
    sw.add_argument("--quiet", action="store_true", help="no progress bar, no console summary")
    sw.set_defaults(func=cmd_sweep)
    # Where the application layer (flexmb.cli) adds its verbs (node, replay, view, bench, ...) and its
    # options to `run`.
    p.verbs = sub
    p.verb_parsers = {"check": c, "run": r, "commands": cm, "tune": tn, "sweep": sw}
    return p


def add_run_hook(run_parser: argparse.ArgumentParser, factory) -> None:
    """Register ``factory(args, scene, model) -> hook | None`` with ``flexmb run``.

    A hook has ``start(sim)``, ``step(sim, result)`` after every step and ``close(sim, summary)``
    (also after a failed or interrupted run); it may add keys to the JSON ``summary``.
    """
    run_parser.get_default("hook_factories").append(factory)


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    """A warning as a user of the command reads it: what, in one line — not the source line that
    raised it (Python's default format quotes our code or NumPy's)."""
    return _bounded(f"flexmb: {category.__name__}: {message}") + "\n"


def main(argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None) -> int:
    previous = warnings.formatwarning
    if not os.environ.get("FLEXMB_DEBUG"):
        warnings.formatwarning = _one_line_warning
    try:
        return _main(argv, parser)
    finally:
        warnings.formatwarning = previous          # a caller in the same process keeps its own format


def _main(argv: list[str] | None, parser: argparse.ArgumentParser | None) -> int:
    _env_defaults()
    args = (parser or build_parser()).parse_args(argv)
    for name in ("until", "dt"):
        v = getattr(args, name, None)
        if v is not None and (not math.isfinite(v) or v <= 0):
            print(f"flexmb {args.verb}: --{name} must be a positive number, got {v}", file=sys.stderr)
            return 1
    try:
        return args.func(args)
    except SceneError as exc:
        print(_bounded(f"flexmb {args.verb}: scene error: {exc}"), file=sys.stderr)
        return 1
    except FlexmbError as exc:
        print(_bounded(f"flexmb {args.verb}: {exc}"), file=sys.stderr)
        return 1
    except OSError as exc:
        # an I/O failure on a path the user gave, after its checks passed (a full disk, a directory
        # removed meanwhile): what failed where, no traceback
        where = f"{path_excerpt(Path(os.fsdecode(exc.filename)))}: " if exc.filename else ""
        print(_bounded(f"flexmb {args.verb}: {where}{exc.strerror or exc}"), file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        # a verb that does not stop on its own after a signal (or a second signal, _StopOnSignal):
        # the exit code of an interrupted run, no traceback
        print(f"flexmb {args.verb}: interrupted", file=sys.stderr)
        return 130


def _bounded(message: str) -> str:
    """A printed error stays short whatever produced it (messages excerpt values; this is the backstop)."""
    return message if len(message) <= MESSAGE_CHARS else message[:MESSAGE_CHARS - 30] + f"… ({len(message)} chars)"


if __name__ == "__main__":
    sys.exit(main())
