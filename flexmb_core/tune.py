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
    """One candidate: what changed, how fast it ran and how far its outputs are from the reference."""

    label: str
    scene: dict
    steps_per_s: float = math.nan
    wall_per_sim_s: float = math.nan
    errors: dict[str, float] = field(default_factory=dict)
    ok: bool = False
    message: str = ""
    constrained: frozenset = frozenset()

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
    scene = scene_from_dict(scene_dict, source=source, overrides={"until": until})
    model = compile_scene(scene)
    sim = Simulator(model)
    sim.warmup()
    sim.initialize()
    kinds = {o.name: o.kind for o in scene.outputs}
    series: dict[str, list] = {k: [] for k in kinds}
    wall = 0.0
    n = int(round(until / sample))
    for k in range(1, n + 1):
        t0 = time.perf_counter()
        sim.run(k * sample)
        wall += time.perf_counter() - t0            # stepping only, not the output sampling
        for name, val in sim.outputs().items():
            series[name].append(_flatten(kinds[name], val))
    return {k: (kinds[k], np.asarray(v)) for k, v in series.items()}, wall, sim.stats.steps


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


def tune(scene: dict, tol: float, until: float, source: str = "<scene>",
         progress: Callable[[Trial], None] | None = None, max_rounds: int = 8,
         outputs: tuple[str, ...] | None = None) -> TuneResult:
    """Greedy search for the cheapest fidelity within ``tol`` (see the module docstring).

    ``outputs``: names of the outputs held to ``tol`` (default: every kinematic output)."""
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
        constrained = frozenset(outputs)
    else:
        constrained = frozenset(k for k, o in declared.items() if o.get("kind") not in RELATIVE)
    if not constrained:
        raise FlexmbError(f"{source}: the scene declares no kinematic output; name the outputs to hold "
                          f"with --outputs (declared: {sorted(declared)})")
    sample = 4.0 * scene.get("solver", {}).get("dt", 1e-3)
    until = max(sample, round(until / sample) * sample)
    ref, ref_wall, _ = _run(reference_scene(scene), until, sample, source)

    def evaluate(label: str, s: dict) -> Trial:
        trial = Trial(label, s, constrained=constrained)
        try:
            run, wall, steps = _run(s, until, sample, source)
        except (ConvergenceError, FlexmbError) as exc:
            trial.message = str(exc)
            return trial
        trial.steps_per_s = steps / max(wall, 1e-12)
        trial.wall_per_sim_s = wall / until
        trial.errors = output_errors(run, ref)
        trial.ok = trial.max_error <= tol
        if progress is not None:
            progress(trial)
        return trial

    baseline = evaluate("as declared", copy.deepcopy(scene))
    trials = [baseline]
    best = baseline
    for _ in range(max_rounds):
        round_trials = []
        for label, move in moves(best.scene):
            cand = move(copy.deepcopy(best.scene))
            if cand is None:
                continue
            t = evaluate(f"{best.label} + {label}" if best is not baseline else label, cand)
            trials.append(t)
            round_trials.append(t)
        passing = [t for t in round_trials if t.ok]
        if not passing:
            break
        fastest = min(passing, key=lambda t: t.wall_per_sim_s)
        if not (fastest.wall_per_sim_s < 0.95 * best.wall_per_sim_s) and best.ok:
            break
        best = fastest
    if not best.ok:
        best = min((t for t in trials if t.ok), key=lambda t: t.wall_per_sim_s, default=best)
    return TuneResult(tol, until, ref_wall / until, baseline, trials, best)


def report_markdown(result: TuneResult, scene_name: str) -> str:
    names = sorted({k for t in result.trials for k in t.errors})
    held = result.baseline.constrained
    lines = [f"# flexmb tune: {scene_name}, tolerance {result.tolerance:g}, horizon {result.until:g} s", "",
             f"Reference (refined scene, Δt / 4): {result.reference_wall_per_sim_s:.3g} s of wall time per "
             "simulated second. Errors: m for positions, rad for orientations and angles, relative for forces "
             "and energy.", "",
             "| candidate | within tol | steps/s | wall s per sim s | "
             + " | ".join(n if n.split(".")[0] in held else f"{n} (reported)" for n in names) + " |",
             "|---|---|---|---|" + "---|" * len(names)]
    for t in result.trials:
        errs = " | ".join(f"{t.errors[n]:.2e}" if n in t.errors else "–" for n in names)
        mark = "**chosen**" if t is result.best else ("yes" if t.ok else ("failed" if t.message else "no"))
        lines.append(f"| {t.label} | {mark} | {t.steps_per_s:.0f} | {t.wall_per_sim_s:.3g} | {errs} |")
    b = result.best
    lines += ["", f"Chosen: **{b.label}**, {b.steps_per_s:.0f} steps/s "
              f"({result.baseline.wall_per_sim_s / b.wall_per_sim_s:.2f}× the scene as declared), "
              f"largest error {b.max_error:.2e}."]
    fails = [t for t in result.trials if t.message]
    if fails:
        lines += ["", "Candidates that failed to run:"] + [f"- {t.label}: {t.message}" for t in fails]
    return "\n".join(lines) + "\n"
