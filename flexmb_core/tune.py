"""``flexmb tune``: the cheapest fidelity of a scene that keeps its declared outputs within a
tolerance of a converged reference ("model only what a scene needs").

The reference refines the scene (frame members: twice the elements; shells: twice the divisions
and the full rule; Δt / 4; full Newton at the scene's tolerance). A greedy search then coarsens the scene one
knob at a time — per group of identical members: the bar variant of a frame actuator, a frame
member's element count halved; per shell: the cheap plate rule, the divisions halved; the time
step doubled; the trapezoidal rule instead of generalized-α; modified Newton — runs every
candidate over the same horizon, keeps the fastest one whose outputs stay within the tolerance,
and repeats until no move pays. Every trial is reported (fidelity, speed, error per output).

Errors are the maximum over the common sample times (every ``4·Δt`` of the scene) of: the
distance for positions and displacements (m), the rotation angle between orientations (rad), the
absolute difference for lengths, velocities and angles, and the difference relative to the
reference's largest magnitude for forces and energies (so ``--tol 1e-4`` means 0.1 mm, 0.1 mrad
and 0.01 %). By default the kinematic outputs (positions, poses, lengths, angles) are held to the
tolerance and forces and energies are reported only — an undamped member's force rings differently
at every Δt and would hold the search at the reference; name outputs to constrain them too.

Where the runs happen is an *evaluator*'s business; the search is the same. :class:`InProcess`
runs them one after another in this process (``--workers 1``). :class:`OnDask` (issue 17, the
default of ``flexmb tune`` where Dask is installed) runs the reference, the scene as declared and
the first round's candidates as Dask tasks at once, then each round's candidates at once. Errors
do not depend on where a run happens (the same code gives the same bits). Speeds do: runs that
share a core, a memory bus or a hyper-threaded core with another run are slowed by it, and the
last run of a round may have the machine to itself. So a round on Dask is only a *screen*: each
run also measures the CPU time of its stepping thread (which time-slicing with other processes
does not inflate), the passing candidates within ``RETIME_BAND`` of the least CPU time are the
finalists, and the finalists — with the current best when it was only screened — are timed again
one at a time on one worker while nothing else of the search runs (``timing: re-timed``). The
choice between candidates and the "pays ≥ 5 %" test use those wall times only, measured as the
sequential search measures them (stepping only, output sampling excluded).
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .errors import ConvergenceError, FlexmbError
from .model.compile import compile_scene
from .scene.loader import scene_from_dict
from .simulator import Simulator

ABSOLUTE = {"node_position", "node_displacement", "member_shape", "shell_point", "shell_shape",
            "actuator_length", "actuator_command", "actuator_velocity", "joint_angle", "section_vectors"}
RELATIVE = {"actuator_force", "energy"}


@dataclass
class Trial:
    """One candidate: what changed, how fast it ran and how far its outputs are from the reference.

    ``wall_per_sim_s`` / ``steps_per_s`` are what the search compares; ``timing`` says how they were
    measured: ``in-process`` (the sequential search: one run at a time in this process),
    ``parallel`` (a Dask worker, other runs of the round at the same time: a screen only) or
    ``re-timed`` (run again alone on one worker). ``screen_*`` keep the first run's wall and
    stepping-thread CPU time per simulated second.
    """

    label: str
    scene: dict
    steps_per_s: float = math.nan
    wall_per_sim_s: float = math.nan
    errors: dict[str, float] = field(default_factory=dict)
    ok: bool = False
    message: str = ""
    constrained: frozenset = frozenset()
    timing: str = "in-process"
    screen_wall_per_sim_s: float = math.nan
    screen_cpu_per_sim_s: float = math.nan

    @property
    def max_error(self) -> float:
        """Largest error among the constrained outputs."""
        return max((v for k, v in self.errors.items() if k.split(".")[0] in self.constrained), default=math.inf)


def _flatten(kind: str, value) -> np.ndarray:
    if kind == "platform_pose":
        return np.concatenate((value["position"], value["orientation_wxyz"]))
    if kind == "shell_point":
        return np.asarray(value["position"], dtype=float)
    if kind == "energy":
        return np.array([value.get("total", 0.0), value.get("strain", 0.0), value.get("kinetic", 0.0)])
    return np.asarray(value, dtype=float).ravel()


def _run(scene_dict: dict, until: float, sample: float, source: str) -> tuple[dict, float, int]:
    """Run a scene dict to ``until``; outputs sampled every ``sample`` s (kind, (n, k) array per
    output), the wall time of the stepping (JIT warm-up excluded) and the step count."""
    series, wall, _, steps = _run_timed(scene_dict, until, sample, source)
    return series, wall, steps


def _run_timed(scene_dict: dict, until: float, sample: float, source: str) -> tuple[dict, float, float, int]:
    """:func:`_run` that also returns the CPU time (s) of this thread while stepping (the flexmb
    step is single-threaded: BLAS at one thread, numba without ``parallel``)."""
    scene = scene_from_dict(scene_dict, source=source, overrides={"until": until})
    model = compile_scene(scene)
    _prime(model, min(until, 2.0 * sample))
    sim = Simulator(model)
    sim.warmup()
    sim.initialize()
    kinds = {o.name: o.kind for o in scene.outputs}
    series: dict[str, list] = {k: [] for k in kinds}
    wall = cpu = 0.0
    n = int(round(until / sample))
    for k in range(1, n + 1):
        t0, c0 = time.perf_counter(), time.thread_time()
        sim.run(k * sample)
        wall += time.perf_counter() - t0            # stepping only, not the output sampling
        cpu += time.thread_time() - c0
        for name, val in sim.outputs().items():
            series[name].append(_flatten(kinds[name], val))
    return {k: (kinds[k], np.asarray(v)) for k, v in series.items()}, wall, cpu, sim.stats.steps


def _prime(model, until: float) -> None:
    """An untimed short run on a throwaway simulator: loads every kernel a step can reach (warmup()
    covers the assembly only), so a process's first run of a kind is not timed with its compilation
    or cache loading — on a Dask worker any candidate may be that first run."""
    sim = Simulator(model)
    sim.warmup()
    try:
        sim.initialize()
        sim.run(until)
    except ConvergenceError:
        pass                                        # the timed run reports it


@dataclass(frozen=True)
class Job:
    """One run of the search: a scene dict over ``until`` s, sampled every ``sample`` s (picklable:
    what a Dask task receives)."""

    scene: dict
    until: float
    sample: float
    source: str


@dataclass
class Measured:
    """What a run returns: sampled outputs (as :func:`_run`), stepping wall and CPU time (s), steps;
    ``message`` when the scene or a step failed (then ``series`` is None)."""

    series: dict | None
    wall: float
    cpu: float
    steps: int
    message: str = ""


def measure(job: Job) -> Measured:
    """Run one candidate (the task of the search). A scene that does not compile or a step that
    does not converge is a :class:`Measured` with its message; anything else raises."""
    try:
        series, wall, cpu, steps = _run_timed(job.scene, job.until, job.sample, job.source)
    except (ConvergenceError, FlexmbError) as exc:
        return Measured(None, math.nan, math.nan, 0, str(exc))
    return Measured(series, wall, cpu, steps)


def _rotation_angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Angle (rad) of the rotation from unit quaternions ``qa`` to ``qb`` (n, 4) (w, x, y, z):
    2·atan2(|v|, |w|) of qa* ⊗ qb, accurate near zero (2·acos(|qa·qb|) has a 3e-8 round-off floor)."""
    wa, va = qa[:, 0], qa[:, 1:]
    wb, vb = qb[:, 0], qb[:, 1:]
    w = wa * wb + np.sum(va * vb, axis=1)
    v = wa[:, None] * vb - wb[:, None] * va - np.cross(va, vb)
    return 2.0 * np.arctan2(np.linalg.norm(v, axis=1), np.abs(w))


def output_errors(run: dict, ref: dict) -> dict[str, float]:
    """Per-output error of a run against the reference (see the module docstring)."""
    out = {}
    for name, (kind, y) in run.items():
        yr = ref[name][1]
        if kind == "platform_pose":
            dp = np.linalg.norm(y[:, :3] - yr[:, :3], axis=1).max()
            out[f"{name}.position"] = float(dp)
            out[f"{name}.orientation"] = float(_rotation_angle(yr[:, 3:], y[:, 3:]).max())
        elif kind in RELATIVE:
            scale = max(float(np.abs(yr).max()), 1e-300)
            out[name] = float(np.abs(y - yr).max() / scale)
        elif kind in ("node_position", "node_displacement", "shell_point"):
            out[name] = float(np.linalg.norm(y - yr, axis=1).max())
        elif kind in ("member_shape", "shell_shape"):
            out[name] = float(np.linalg.norm((y - yr).reshape(y.shape[0], -1, 3), axis=2).max())
        else:
            out[name] = float(np.abs(y - yr).max())
    return out


# -- fidelity moves ---------------------------------------------------------------------------
def _member_groups(scene: dict) -> dict[tuple, list[str]]:
    """Members with identical fidelity-relevant definitions (tuned together, e.g. six legs)."""
    groups: dict[tuple, list[str]] = {}
    for name, m in scene.get("members", {}).items():
        act = m.get("actuator") or {}
        key = (m["kind"], act.get("variant", "frame") if m["kind"] == "actuator" else "",
               m.get("elements"), m.get("order"), m["section"], m["material"])
        groups.setdefault(key, []).append(name)
    return groups


def _is_frame(m: dict) -> bool:
    return m["kind"] == "frame" or (m["kind"] == "actuator" and (m.get("actuator") or {}).get("variant", "frame") == "frame")


def moves(scene: dict) -> list[tuple[str, Callable[[dict], dict | None]]]:
    """Every single-knob coarsening applicable to ``scene`` (label, scene → coarser scene)."""
    out = []
    for names in _member_groups(scene).values():
        m0 = scene["members"][names[0]]
        tag = names[0] if len(names) == 1 else f"{names[0]}…{names[-1]} ({len(names)})"
        if m0["kind"] == "actuator" and _is_frame(m0) and not m0.get("via") and not m0.get("arc"):
            def to_bar(s, names=names):
                for n in names:
                    m = s["members"][n]
                    m["actuator"] = dict(m.get("actuator") or {}, variant="bar")
                    for k in ("elements", "order", "up", "integration", "mass"):
                        m.pop(k, None)
                return s
            out.append((f"{tag}: bar actuator", to_bar))
        if _is_frame(m0) and m0.get("elements", 4) > 1 and not m0.get("via"):
            def halve(s, names=names):
                for n in names:
                    s["members"][n]["elements"] = max(1, s["members"][n].get("elements", 4) // 2)
                return s
            out.append((f"{tag}: {max(1, m0.get('elements', 4) // 2)} elements", halve))
    for name, sh in scene.get("shells", {}).items():
        quad = sh.get("quadrature", {})
        if (quad.get("in_plane", 4), quad.get("thickness", 3)) != (3, 2):
            def cheap_rule(s, name=name):
                s["shells"][name]["quadrature"] = {"in_plane": 3, "thickness": 2}
                return s
            out.append((f"{name}: 3×3 × 2 point rule", cheap_rule))
        div = sh["mesh"]["divisions"]
        div = div if isinstance(div, list) else [div]
        if max(div) > 1:
            def halve_mesh(s, name=name):
                d = s["shells"][name]["mesh"]["divisions"]
                s["shells"][name]["mesh"]["divisions"] = [max(1, x // 2) for x in d] if isinstance(d, list) else max(1, d // 2)
                return s
            out.append((f"{name}: divisions halved", halve_mesh))
    solver = scene.get("solver", {})
    out.append(("Δt × 2", lambda s: s["solver"].update(dt=2.0 * s["solver"].get("dt", 1e-3)) or s))
    if solver.get("integrator", "generalized_alpha") != "newmark":
        out.append(("trapezoidal rule (Newmark β = ¼, γ = ½)",
                    lambda s: s["solver"].update(integrator="newmark", beta=0.25, gamma=0.5) or s))
    if solver.get("newton", "full") != "modified":
        out.append(("modified Newton", lambda s: s["solver"].update(newton="modified") or s))
    return out


def reference_scene(scene: dict) -> dict:
    """The converged reference: frame members ×2 elements, shells ×2 divisions with the full
    rule, Δt / 4, full Newton at the scene's own tolerance (a tighter one can sit below the
    round-off floor of a stiff model's statics)."""
    s = copy.deepcopy(scene)
    for m in s.get("members", {}).values():
        if _is_frame(m) and not m.get("via"):
            m["elements"] = 2 * m.get("elements", 4)
    for sh in s.get("shells", {}).values():
        d = sh["mesh"]["divisions"]
        sh["mesh"]["divisions"] = [2 * x for x in d] if isinstance(d, list) else 2 * d
        sh.pop("quadrature", None)
    sol = s.setdefault("solver", {})
    sol["dt"] = sol.get("dt", 1e-3) / 4.0
    sol["newton"] = "full"
    return s


@dataclass
class TuneResult:
    tolerance: float
    until: float
    reference_wall_per_sim_s: float
    baseline: Trial
    trials: list[Trial]
    best: Trial
    workers: int = 1                   # Dask worker threads (1: in this process)
    scheduler: str = ""                # the Dask scheduler's address ("" in this process)


# -- where the runs happen ----------------------------------------------------------------------------
RETIME_BAND = 1.25      # finalists: passing candidates within 25 % of the least screened CPU time


class InProcess:
    """Every run in this process, one after another (the sequential search): each wall time is taken
    with nothing else of the search running, so no run is timed twice."""

    workers, scheduler, timing = 1, "", "in-process"

    def __init__(self, task: Callable[[Job], Measured] = measure):
        self.task = task                    # what runs a Job (default measure)

    def runs(self, jobs: list[Job], on_result: Callable[[int, Measured], None]) -> list[Measured]:
        out = []
        for i, job in enumerate(jobs):
            out.append(self.task(job))
            on_result(i, out[-1])
        return out

    def finalists(self, passing: list[Trial]) -> list[Trial]:
        return passing

    def retime(self, trials: list[Trial], job: Callable[[Trial], Job]) -> None:
        return None


class OnDask:
    """Runs as tasks of a Dask client (see the module docstring): a batch at once, finalists re-timed
    one at a time on one worker."""

    timing = "parallel"

    def __init__(self, client, task: Callable[[Job], Measured] = measure):
        from .study.tasks import cluster_facts

        self.client = client
        self.task = task                    # what runs a Job: a module-level function the workers import
        self.scheduler, self.workers = cluster_facts(client)
        self._worker: str | None = None

    def runs(self, jobs: list[Job], on_result: Callable[[int, Measured], None]) -> list[Measured]:
        from .study.tasks import run_all

        return run_all(self.client, self.task, jobs, name="flexmb-tune", on_result=on_result)

    def finalists(self, passing: list[Trial]) -> list[Trial]:
        least = min(t.screen_cpu_per_sim_s for t in passing)
        return [t for t in passing if t.screen_cpu_per_sim_s <= RETIME_BAND * least]

    def retime(self, trials: list[Trial], job: Callable[[Trial], Job]) -> None:
        from .study.tasks import run_alone, timing_worker

        self._worker = self._worker or timing_worker(self.client)
        for t in trials:
            j = job(t)
            m = run_alone(self.client, self.task, j, self._worker, name="flexmb-tune-retime")
            if not m.message:                   # the same run succeeded once; kept as screened otherwise
                _set_speed(t, m, j.until)
                t.timing = "re-timed"


def _set_speed(t: Trial, m: Measured, until: float) -> None:
    t.steps_per_s = m.steps / max(m.wall, 1e-12)
    t.wall_per_sim_s = m.wall / until


def held_outputs(scene: dict, source: str, outputs: tuple[str, ...] | None) -> frozenset:
    """The outputs held to the tolerance (``outputs``, or every kinematic one); checks the scene can
    be tuned. Raises :class:`FlexmbError` naming the problem."""
    if scene.get("solver", {}).get("analysis", "dynamic") != "dynamic":
        raise FlexmbError(f"{source}: tune needs a dynamic scene (solver.analysis: dynamic)")
    declared = scene.get("outputs") or {}
    if not declared:
        raise FlexmbError(f"{source}: tune compares the scene's declared outputs, and it declares none")
    if outputs:
        unknown = sorted(set(outputs) - set(declared))
        if unknown:
            raise FlexmbError(f"{source}: --outputs names {unknown}, which the scene does not declare; "
                              f"declared: {sorted(declared)}")
        return frozenset(outputs)
    constrained = frozenset(k for k, o in declared.items() if o.get("kind") not in RELATIVE)
    if not constrained:
        raise FlexmbError(f"{source}: the scene declares no kinematic output; name the outputs to hold "
                          f"with --outputs (declared: {sorted(declared)})")
    return constrained


def _candidates(best: Trial, baseline: Trial) -> list[tuple[str, dict]]:
    """Every single-knob coarsening of ``best`` (labels carry the path from the scene as declared)."""
    out = []
    for label, move in moves(best.scene):
        cand = move(copy.deepcopy(best.scene))
        if cand is not None:
            out.append((f"{best.label} + {label}" if best is not baseline else label, cand))
    return out


def tune(scene: dict, tol: float, until: float, source: str = "<scene>",
         progress: Callable[[Trial], None] | None = None, max_rounds: int = 8,
         outputs: tuple[str, ...] | None = None, evaluator: InProcess | OnDask | None = None) -> TuneResult:
    """Greedy search for the cheapest fidelity within ``tol`` (see the module docstring).

    ``outputs``: names of the outputs held to ``tol`` (default: every kinematic output).
    ``evaluator``: where the runs happen (default :class:`InProcess`); ``progress(trial)`` is called
    when a trial's run arrives and again when it has been re-timed."""
    constrained = held_outputs(scene, source, outputs)
    ev = evaluator or InProcess()
    sample = 4.0 * scene.get("solver", {}).get("dt", 1e-3)
    until = max(sample, round(until / sample) * sample)
    ref: list[Measured] = []

    def job(s: dict | Trial) -> Job:
        return Job(s.scene if isinstance(s, Trial) else s, until, sample, source)

    def to_trial(label: str, s: dict, m: Measured) -> Trial:
        t = Trial(label, s, constrained=constrained, timing=ev.timing)
        if m.message:
            t.message = m.message
            return t
        _set_speed(t, m, until)
        t.screen_wall_per_sim_s, t.screen_cpu_per_sim_s = m.wall / until, m.cpu / until
        t.errors = output_errors(m.series, ref[0].series)
        t.ok = t.max_error <= tol
        return t

    def evaluate(cands: list[tuple[str, dict]], with_reference: bool = False) -> list[Trial]:
        k0 = int(with_reference)
        jobs = ([job(reference_scene(scene))] if with_reference else []) + [job(s) for _, s in cands]
        trials: list[Trial | None] = [None] * len(cands)
        arrived: dict[int, Measured] = {}

        def on_result(i: int, m: Measured) -> None:      # trials need the reference: held until it is in
            arrived[i] = m
            if with_reference and not ref and 0 in arrived:
                if arrived[0].message:
                    raise FlexmbError(f"{source}: the refined reference (tune's yardstick) did not run: "
                                      f"{arrived[0].message}")
                ref.append(arrived[0])
            if not ref:
                return
            for j in sorted(k for k in arrived if k >= k0 and trials[k - k0] is None):
                label, s = cands[j - k0]
                trials[j - k0] = to_trial(label, s, arrived[j])
                if progress is not None:
                    progress(trials[j - k0])

        ev.runs(jobs, on_result)
        return trials

    baseline = Trial("as declared", copy.deepcopy(scene))
    first = evaluate([("as declared", baseline.scene)] + _candidates(baseline, baseline), with_reference=True)
    baseline, round_trials = first[0], first[1:]
    trials = [baseline]
    best = baseline
    for r in range(max_rounds):
        if r:
            round_trials = evaluate(_candidates(best, baseline))
        trials += round_trials
        passing = [t for t in round_trials if t.ok]
        if not passing:
            break
        finalists = ev.finalists(passing)
        again = ([best] if best.ok and best.timing == "parallel" else []) + finalists
        ev.retime(again, job)
        if progress is not None:
            for t in again:
                if t.timing == "re-timed":
                    progress(t)
        fastest = min(finalists, key=lambda t: t.wall_per_sim_s)
        if not (fastest.wall_per_sim_s < 0.95 * best.wall_per_sim_s) and best.ok:
            break
        best = fastest
    if not best.ok:
        best = min((t for t in trials if t.ok), key=lambda t: t.wall_per_sim_s, default=best)
    return TuneResult(tol, until, ref[0].wall / until, baseline, trials, best, ev.workers, ev.scheduler)


def report_markdown(result: TuneResult, scene_name: str) -> str:
    names = sorted({k for t in result.trials for k in t.errors})
    held = result.baseline.constrained
    lines = [f"# flexmb tune: {scene_name}, tolerance {result.tolerance:g}, horizon {result.until:g} s", "",
             f"Reference (refined scene, Δt / 4): {result.reference_wall_per_sim_s:.3g} s of wall time per "
             "simulated second. Errors: m for positions, rad for orientations and angles, relative for forces "
             "and energy.", "", _timing_note(result), "",
             "| candidate | within tol | steps/s | wall s per sim s | timed | "
             + " | ".join(n if n.split(".")[0] in held else f"{n} (reported)" for n in names) + " |",
             "|---|---|---|---|---|" + "---|" * len(names)]
    for t in result.trials:
        errs = " | ".join(f"{t.errors[n]:.2e}" if n in t.errors else "–" for n in names)
        mark = "**chosen**" if t is result.best else ("yes" if t.ok else ("failed" if t.message else "no"))
        lines.append(f"| {t.label} | {mark} | {t.steps_per_s:.0f} | {t.wall_per_sim_s:.3g} | {t.timing} | {errs} |")
    b = result.best
    lines += ["", f"Chosen: **{b.label}**, {b.steps_per_s:.0f} steps/s "
              f"({result.baseline.wall_per_sim_s / b.wall_per_sim_s:.2f}× the scene as declared), "
              f"largest error {b.max_error:.2e}."]
    fails = [t for t in result.trials if t.message]
    if fails:
        lines += ["", "Candidates that failed to run:"] + [f"- {t.label}: {t.message}" for t in fails]
    return "\n".join(lines) + "\n"


def _timing_note(result: TuneResult) -> str:
    if not result.scheduler:
        return "Timed in this process, one run after another (`timed: in-process`)."
    return (f"Runs on Dask ({result.workers} workers, scheduler {result.scheduler}): errors and a first timing "
            "of each round's candidates in parallel (`timed: parallel`, a screen only: runs at the same time "
            f"slow each other down); the passing candidates within {RETIME_BAND:g}× the least stepping CPU time, "
            "and the scene they are compared with, timed again one at a time on one worker (`timed: re-timed`). "
            "Only re-timed wall times decide; the reference's time above is from the parallel round.")
