"""``flexmb calibrate``: the verb's flags, progress, report and files (the numerics:
:mod:`flexmb_core.study.calibrate`; the bag side: :mod:`flexmb_io.bag.calibrate`)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from flexmb_core.errors import writable_dir, writable_file

DEFAULT_OUT = "build/calibrate"

HELP = """Identify scene parameters so the twin reproduces a recording: the bag's commands drive the
twin, its recorded outputs are the measurements; bounded nonlinear least squares (scipy) with the
Jacobian's columns computed in parallel on Dask (a local cluster, or --scheduler ADDRESS).

  flexmb calibrate BAG --fit materials.steel.E --fit materials.steel.eta=1e6:1e7 \\
      --fit point_masses.payload_a.mass --override materials.steel.E=1.7e11

The fit starts from the scene's values (the bag's scene.yaml, or --scene; --override edits it).
Without LO:HI a parameter is bounded to [start/10, start*10]. Measured channels (--outputs picks
by name or by the part after the dot): actuators.length (m), actuators.force (N),
actuators.velocity (m/s), joints.angle (rad), <pose>.position (m), <pose>.orientation (rad).
Each channel is weighed by its noise level: --noise CHANNEL=SIGMA when known, else estimated from
the fit's residuals. Standard errors come from the Jacobian at the solution.

Writes OUT/<scene>_calibrated.yaml (the scene with the identified values), OUT/calibration.json
and OUT/calibration.md. Exit codes: 0 the fit converged; 3 it did not (evaluation budget spent);
1 bad input.
"""


def _flatten(items) -> list[str]:
    return [x for group in (items or []) for x in group]


def _noise(items: list[str]) -> dict[str, float]:
    from flexmb_core.study.calibrate import CalibrationError

    out = {}
    for item in items:
        name, _, v = item.partition("=")
        try:
            sigma = float(v)
        except ValueError:
            sigma = math.nan
        if not name or not (sigma > 0 and math.isfinite(sigma)):
            raise CalibrationError(f"--noise {item!r}: expected CHANNEL=SIGMA with SIGMA > 0, e.g. actuators.force=0.5")
        out[name] = sigma
    return out


def report_lines(result, bag: str) -> list[str]:
    """A readable table of the identified values and the channels' residuals."""
    lines = [f"calibration of {bag}: {'converged' if result.success else 'NOT CONVERGED'} ({result.message}); "
             f"{result.evaluations} twin runs ({result.jacobians} Jacobians), {result.passes} noise pass(es), "
             f"{result.wall_time_s:.1f} s",
             f"  {'parameter':34s} {'start':>12s} {'identified':>12s} {'std error':>10s} {'change':>8s}"]
    for k, s, v, e, b in zip(result.keys, result.start, result.values, result.std_errors, result.at_bound):
        change = (v / s - 1.0) * 100 if s else math.nan
        lines.append(f"  {k:34s} {s:12.6g} {v:12.6g} {e:10.3g} {change:+7.2f}%" + ("  AT BOUND" if b else ""))
    lines.append(f"  {'channel':28s} {'samples':>8s} {'rms start':>11s} {'rms':>11s} {'noise':>11s}")
    for c in result.channels:
        lines.append(f"  {c.name:28s} {c.samples:8d} {c.rms_start:11.4g} {c.rms:11.4g} {c.sigma:11.4g} {c.unit}"
                     + (" (given)" if c.sigma_given else ""))
    return lines


def as_dict(result, *, bag: str, scene: str, workers: int, scheduler: str) -> dict:
    """The JSON of a calibration (documented in README: flexmb calibrate)."""
    return {
        "bag": bag, "calibrated_scene": scene, "success": result.success, "message": result.message,
        "parameters": [{"key": k, "start": float(s), "value": float(v), "std_error": float(e),
                        "lower": float(lo), "upper": float(hi), "at_bound": b}
                       for k, s, v, e, lo, hi, b in zip(result.keys, result.start, result.values, result.std_errors,
                                                         result.lower, result.upper, result.at_bound)],
        "correlation": [[None if not math.isfinite(x) else float(x) for x in row] for row in result.correlation],
        "channels": [{"name": c.name, "unit": c.unit, "samples": c.samples, "noise": c.sigma,
                      "noise_given": c.sigma_given, "rms_start": c.rms_start, "rms": c.rms} for c in result.channels],
        "passes": result.passes, "evaluations": result.evaluations, "jacobians": result.jacobians,
        "wall_time_s": result.wall_time_s, "workers": workers, "scheduler": scheduler,
        "history": result.history,
    }


def cmd_calibrate(args: argparse.Namespace) -> int:
    from flexmb_core.study.calibrate import CalibrationError, fit, parse_fit
    from flexmb_core.study.cluster import connect

    from .calibrate import calibrated_scene_text, measured_rms, read_measurements, residuals, start_values

    params = [parse_fit(x) for x in _flatten(args.fit)]
    if not params:
        raise CalibrationError("flexmb calibrate needs at least one --fit KEY[=LO:HI]")
    keys = [p.key for p in params]
    if len(set(keys)) != len(keys):
        raise CalibrationError(f"--fit names a key twice: {keys}")
    if args.workers is not None and args.workers < 1:
        raise CalibrationError(f"--workers must be a positive integer, got {args.workers}")
    if args.until is not None and not args.until > 0:
        raise CalibrationError(f"--until must be a positive time (s), got {args.until}")
    if not (math.isfinite(args.diff_step) and args.diff_step > 0):
        raise CalibrationError(f"--diff-step must be a positive relative step, got {args.diff_step}")
    if args.max_evaluations < 1:
        raise CalibrationError(f"--max-evaluations must be a positive integer, got {args.max_evaluations}")
    out = writable_dir(args.out, "--out")       # before the fit: no work lost to a bad path
    if args.json:
        writable_file(args.json, "--json", inputs=(args.bag, args.scene))
    noise = _noise(_flatten(args.noise))
    overrides = _flatten(args.override)
    outputs = [x for x in (args.outputs or "").split(",") if x] or None
    meas = read_measurements(args.bag, keys, outputs=outputs, until=args.until, scene_path=args.scene,
                             overrides=overrides)
    start = start_values(meas.setup, overrides, keys)
    units = {c.name: c.unit for c in meas.channels}

    def progress(entry: dict) -> None:
        if not args.quiet:
            vals = ", ".join(f"{k.rsplit('.', 1)[-1]}={v:.6g}" for k, v in zip(keys, entry["theta"]))
            print(f"  run: {vals}" + ("" if entry["ok"] else f"  FAILED: {entry['error'][:200]}"), flush=True)

    with connect(args.scheduler, args.workers or min(len(keys), _default_workers()), verb="flexmb calibrate") as client:
        workers, scheduler = len(client.nthreads()), str(client.scheduler.address)
        result = fit(residuals, meas, params, start, client, measured_rms=measured_rms(meas), units=units,
                     noise=noise, diff_step=args.diff_step, max_evaluations=args.max_evaluations, progress=progress)
    scene_file = out / f"{_scene_name(meas.setup)}_calibrated.yaml"
    header = (f"# Calibrated by `flexmb calibrate {args.bag} " + " ".join(f"--fit {k}" for k in keys) + "`:\n"
              + "".join(f"#   {k} = {v:.9g} ± {e:.3g} (1σ; start {s:.6g})\n"
                        for k, v, e, s in zip(keys, result.values, result.std_errors, result.start))
              + "# Comments of the original scene are not carried over.\n")
    scene_file.write_text(calibrated_scene_text(meas.setup, overrides, result, header), encoding="utf-8")
    lines = report_lines(result, args.bag)
    doc = as_dict(result, bag=str(args.bag), scene=str(scene_file), workers=workers, scheduler=scheduler)
    (out / "calibration.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    (out / "calibration.md").write_text("```\n" + "\n".join(lines) + "\n```\n", encoding="utf-8")
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print("\n".join(lines) + f"\nwrote {scene_file}, {out / 'calibration.json'}")
    return 0 if result.success else 3


def _default_workers() -> int:
    from flexmb_core.study.cluster import default_workers

    return default_workers()


def _scene_name(setup) -> str:
    from flexmb_core.scene.loader import parse_yaml

    data = parse_yaml(setup.scene_text)
    return str(data.get("name", "scene")) if isinstance(data, dict) else "scene"


def register(verbs) -> None:
    """Add ``calibrate`` to the verbs."""
    c = verbs.add_parser("calibrate", help="identify scene parameters from a recording (least squares on Dask)",
                         description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("bag", metavar="BAG", help="rosbag2 directory (or .mcap) from flexmb run/node --mcap")
    c.add_argument("--fit", metavar="KEY[=LO:HI]", nargs="+", action="append", required=True,
                   help="a scene key to identify, optionally with bounds (repeatable)")
    c.add_argument("--outputs", metavar="LIST", help="comma-separated measured channels (default: every one recorded)")
    c.add_argument("--noise", metavar="CHANNEL=SIGMA", nargs="+", action="append",
                   help="known measurement noise of a channel, in its unit (others are estimated)")
    c.add_argument("--scene", metavar="PATH", help="start from this scene file instead of the recorded one")
    c.add_argument("--override", metavar="KEY=VALUE", nargs="+", action="append",
                   help="edit the scene before fitting (e.g. the start of a fitted key)")
    c.add_argument("--until", type=float, metavar="T", help="use the recording up to T s of simulated time")
    c.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler (default: a local cluster)")
    c.add_argument("--workers", type=int, metavar="N",
                   help="local cluster size (default: one per fitted key, at most one per core)")
    c.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help=f"output directory (default {DEFAULT_OUT})")
    c.add_argument("--json", metavar="OUT", help="also write the calibration JSON here")
    c.add_argument("--diff-step", type=float, default=1e-3, metavar="H",
                   help="forward-difference step relative to the scaled unknowns (default 1e-3)")
    c.add_argument("--max-evaluations", type=int, default=100, metavar="N",
                   help="residual evaluations per noise pass (default 100)")
    c.add_argument("--quiet", action="store_true", help="no line per twin run")
    c.set_defaults(func=cmd_calibrate)

