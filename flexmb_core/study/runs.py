"""One run of a study: its effective scene, its key, and the task a worker executes.

A run is keyed by the sha256 of the effective scene (the YAML after the run's edits, written
canonically: anchors expanded, one layout, keys in the file's order) together with ``until``, the
chosen outputs and the sampling period — what determines its row. :func:`run_one` is the Dask
task; it does what ``flexmb run`` does (load, compile, warm up, initialize, step to ``until``)
and, in the same loop, keeps the maximum, minimum and RMS over time of the chosen outputs. It
never raises: a run that fails is a row with ``ok: false`` and its error.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import socket
import time
from dataclasses import dataclass
from typing import Any

import yaml

from ..errors import ConvergenceError, FlexmbError, SceneError
from ..scene.overrides import set_path

FORMAT = 1                       # bump when a row's meaning changes: old run files are recomputed
SHAPE_KINDS = ("member_shape", "shell_shape")   # not chosen by default (one column per coordinate)
SUMMARY_KEYS = ("steps", "sim_time_s", "wall_time_s", "rtf", "steps_per_s", "newton_iterations_mean",
                "newton_iterations_max", "unconverged_steps", "substepped_steps", "guard_rejected_steps",
                "max_relative_residual", "jit_warmup_s", "dt", "integrator")
STATS = ("final", "max", "min", "rms")


class _CanonicalDumper(yaml.SafeDumper):
    """YAML without anchors (shared blocks written out in full)."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def canonical_yaml(data: dict) -> str:
    """The scene mapping as canonical YAML: no anchors, one layout, floats as ``repr`` (exact). Keys
    keep the file's order: it numbers nodes and members, so it decides the floating-point sums."""
    return yaml.dump(data, Dumper=_CanonicalDumper, sort_keys=False, allow_unicode=True, width=1 << 16)


@dataclass(frozen=True)
class RunSpec:
    """Everything a worker needs for one run (picklable; no file access needed on the worker)."""

    key: str                           # sha256 hex of (scene_yaml, until, outputs, every, FORMAT)
    params: dict                       # {"materials.steel.E": 2.1e11, ...}
    scene_yaml: str                    # effective scene, canonical
    source: str                        # the scene file the run derives from (for error messages)
    until: float
    outputs: tuple[str, ...]           # output selectors: "leg1_force", "platform.position"
    every: int = 1                     # sample the outputs every k steps


def run_key(scene_yaml: str, until: float, outputs: tuple[str, ...], every: int) -> str:
    blob = json.dumps({"format": FORMAT, "scene": scene_yaml, "until": float(until), "outputs": list(outputs),
                       "every": int(every)}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode("utf-8")).hexdigest()


def effective_scene(base: dict, params: dict[str, Any]) -> dict:
    """A copy of the parsed scene with the run's parameter values set (``solver.X`` included)."""
    data = copy.deepcopy(base)
    for key, value in params.items():
        path = key.split(".")
        if path[0] == "solver" and len(path) == 2 and not isinstance(data.get("solver"), dict):
            data["solver"] = {}
        set_path(data, path, value, item=f"{key}={value}", flag="--param")
    return data


def default_outputs(data: dict) -> tuple[str, ...]:
    """Every output the scene declares except whole shapes."""
    outs = data.get("outputs") or {}
    return tuple(k for k, v in outs.items() if not (isinstance(v, dict) and v.get("kind") in SHAPE_KINDS))


def make_spec(base: dict, params: dict, *, source: str, until: float | None, outputs: tuple[str, ...] | None,
              every: int = 1) -> RunSpec:
    """The run of ``params`` on the parsed scene ``base``; ``until`` None: the scene's ``solver.until``."""
    from ..scene.schema import SolverSpec

    data = effective_scene(base, params)
    if until is None:
        solver = data.get("solver") if isinstance(data.get("solver"), dict) else {}
        until = solver.get("until", SolverSpec().until)
        until = float(until) if isinstance(until, (int, float)) and not isinstance(until, bool) else math.nan
    outs = tuple(outputs) if outputs else default_outputs(data)
    text = canonical_yaml(data)
    return RunSpec(run_key(text, until, outs, every), dict(params), text, source, float(until), outs, int(every))


# -- the task ------------------------------------------------------------------------------------

def flatten(name: str, value: Any) -> list[tuple[str, float]]:
    """An output value as named scalars: ``platform.position.0``, ``energy.kinetic``, ``leg1_force``."""
    if isinstance(value, dict):
        return [leaf for k, v in value.items() for leaf in flatten(f"{name}.{k}", v)]
    if isinstance(value, (list, tuple)):
        return [leaf for i, v in enumerate(value) for leaf in flatten(f"{name}.{i}", v)]
    return [(name, float(value))]


def _selected(leaf: str, selectors: tuple[str, ...]) -> bool:
    return any(leaf == s or leaf.startswith(s + ".") for s in selectors)


class _Sampler:
    """Running max / min / sum of squares of the chosen output leaves."""

    def __init__(self, sim, selectors: tuple[str, ...]):
        declared = {o.name: o for o in sim.model.scene.outputs}
        unknown = [s for s in selectors if s.split(".")[0] not in declared]
        if unknown:
            raise SceneError(sim.model.scene.source, f"--outputs {unknown}: the scene declares no such output "
                                                     f"(has {sorted(declared)})")
        self.outputs = [declared[n] for n in dict.fromkeys(s.split(".")[0] for s in selectors)]
        self.selectors = selectors
        self.needs_energy = any(o.kind == "energy" for o in self.outputs)
        self.names: list[str] | None = None
        self.stats: dict[str, list[float]] = {}
        self.samples = 0

    def values(self, sim) -> list[tuple[str, float]]:
        from ..observers import evaluate_output

        e = sim.energy() if self.needs_energy else None
        leaves = [leaf for o in self.outputs
                  for leaf in flatten(o.name, evaluate_output(sim.model, sim.ws, sim.state, o, e))]
        return [(k, v) for k, v in leaves if _selected(k, self.selectors)]

    def sample(self, sim) -> None:
        leaves = self.values(sim)
        if self.names is None:
            self.names = [k for k, _ in leaves]
            missing = [s for s in self.selectors if not any(_selected(k, (s,)) for k in self.names)]
            if missing:
                raise SceneError(sim.model.scene.source, f"--outputs {missing}: no such output part "
                                                         f"(parts: {self.names})")
            self.stats = {k: [-math.inf, math.inf, 0.0] for k in self.names}
        for k, v in leaves:
            s = self.stats[k]
            s[0] = max(s[0], v)
            s[1] = min(s[1], v)
            s[2] += v * v
        self.samples += 1

    def result(self, sim) -> dict[str, dict[str, float]]:
        out: dict[str, dict[str, float]] = {s: {} for s in STATS}
        for k, v in self.values(sim):
            out["final"][k] = v
        for k, (hi, lo, sq) in self.stats.items():
            out["max"][k], out["min"][k] = hi, lo
            out["rms"][k] = math.sqrt(sq / self.samples) if self.samples else math.nan
        return out


def run_one(spec: RunSpec) -> dict:
    """Execute one run (the Dask task). Returns its row (see :func:`flexmb_core.study.table.columns`)."""
    t_start = time.perf_counter()
    row: dict[str, Any] = {"key": spec.key, "params": spec.params, "until": spec.until,
                           "outputs": list(spec.outputs), "every": spec.every, "ok": False, "completed": False,
                           "converged": False, "error": "", "error_kind": "", "summary": {}, "samples": 0,
                           "tracking": {}, **{s: {} for s in STATS},
                           "worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        _simulate(spec, row)
    except SceneError as exc:
        row.update(error=f"scene error: {exc}", error_kind="scene")
    except ConvergenceError as exc:
        row.update(error=str(exc), error_kind="convergence")
    except FlexmbError as exc:
        row.update(error=str(exc), error_kind="flexmb")
    except Exception as exc:  # noqa: BLE001 - a run's failure is data; the sweep goes on
        row.update(error=f"{type(exc).__name__}: {exc}", error_kind="unexpected")
    row["task_wall_s"] = time.perf_counter() - t_start
    return row


def _simulate(spec: RunSpec, row: dict) -> None:
    # The same sequence as `flexmb run` (cli.cmd_run), so a row's values equal that command's.
    from ..model.compile import compile_scene
    from ..scene.loader import parse_yaml, scene_from_dict
    from ..simulator import Simulator
    from ..tracking import PoseTracker

    scene = scene_from_dict(parse_yaml(spec.scene_yaml), source=spec.source, overrides={"until": spec.until})
    model = compile_scene(scene)
    sim = Simulator(model)
    warm = sim.warmup()
    sim.initialize()
    until = scene.solver.until
    tracker = PoseTracker(model)
    sampler = _Sampler(sim, spec.outputs)
    sampler.sample(sim)
    every = max(1, spec.every)

    def on_step(s, res):
        tracker.update(s.state.t, s.state.q)
        if s.stats.steps % every == 0 or s.state.t >= until - 1e-12 * max(1.0, until):
            sampler.sample(s)

    error = ""
    try:
        sim.run(until, callback=on_step)
    except ConvergenceError as exc:
        error = str(exc)
    summary = sim.summary()
    summary.update({"jit_warmup_s": warm, "dt": scene.solver.dt, "integrator": scene.solver.integrator})
    row["summary"] = {k: summary[k] for k in SUMMARY_KEYS}
    row.update(sampler.result(sim))
    row["samples"] = sampler.samples
    if tracker.active:
        row["tracking"] = {k: v for k, v in tracker.summary().items() if k != "output"}
    row.update(completed=not error, error=error, error_kind="convergence" if error else "",
               converged=not error and summary["unconverged_steps"] == 0)
    row["ok"] = row["completed"]
