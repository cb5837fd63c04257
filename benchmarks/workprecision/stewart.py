"""The Stewart platform twin (seed appendix, SPEC §6.1): 20 s appendix trajectory, commands every step.

flexmb runs the shipped scenes as ``benchmarks/stewart_platform.py`` builds them (``scene_dict``:
``scenes/stewart_platform_bars.yaml`` for bar legs, ``scenes/stewart_platform.yaml`` for frame legs,
elements per leg edited), starting from the static equilibrium (``stewart_platform._start``), with
the variant's order, integrator and Newton strategy. Errors against the stored converged reference
``benchmarks/reference/stewart.csv`` (frame legs, 8 cubic el./leg, Δt = 0.25 ms, Newton tolerance
1e-11, as in ``docs/benchmarks/stewart.md``), at the 0.1 s marks over 0–T:

* ``error`` — max |platform centroid − reference| (m);
* ``error_orientation_rad`` — max rotation angle between the platform orientations (rad);
* ``error_final`` — centroid distance at the last mark (m).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from flexmb_core.model.compile import compile_scene
from flexmb_core.observers import PlatformObserver
from flexmb_core.scene.loader import scene_from_dict
from flexmb_core.simulator import Simulator

from benchmarks import stewart_platform as sp

from . import core

NAME = "stewart"
TITLE = "Stewart platform twin (SPEC §6.1), appendix trajectory"
REFERENCE = core.REFERENCE_DIR / "stewart.csv"
MARK = 0.1                   # s; a multiple of every Δt of the sweep
UNTIL = 20.0
UNTIL_QUICK = 2.0
ERROR_UNIT = "m"
ERROR_MEASURE = "max over 0.1 s marks of |platform centroid − converged reference| (m)"
FINE = core.Variant(NAME, dt=2.5e-4, elements=8, order=3, rho_inf=0.9, newton="modified")
FINE_TOLERANCE = sp.TIGHT
BARS = dict(legs="bar", elements=1, order=1, rho_inf=0.9)      # the shipped twin: bar legs, gen-α 0.9, modified
FRAME = dict(legs="frame", rho_inf=0.9)


def variants(quick: bool) -> list[core.Variant]:
    """The sweep: families (legs, elements per leg, order, integrator, Newton) × Δt."""
    ms = 1e-3
    if quick:
        return core.sweep(NAME, [BARS], (4 * ms, 2 * ms, 1 * ms))
    fams = [BARS]                                                                        # 0
    fams += [dict(BARS, newton="full"), dict(BARS, integrator="newmark")]                # 1–2
    fams += [dict(BARS, rho_inf=r) for r in (0.5, 0.8)]                                  # 3–4
    fams += [dict(FRAME, elements=n) for n in (1, 2, 4)]                                 # 5–7
    fams += [dict(FRAME, elements=1, order=o) for o in (2, 4)]                           # 8–9
    per = {0: (4 * ms, 2 * ms, 1 * ms, 0.5 * ms), 1: (2 * ms, 1 * ms), 2: (2 * ms, 1 * ms), 3: (1 * ms,),
           4: (1 * ms,), 5: (2 * ms, 1 * ms), 6: (1 * ms,), 7: (2 * ms, 1 * ms), 8: (1 * ms,), 9: (1 * ms,)}
    return core.sweep(NAME, fams, per)


def until(quick: bool) -> float:
    return UNTIL_QUICK if quick else UNTIL


def scene_dict(v: core.Variant, t_end: float, tolerance: float | None = None) -> dict:
    """The variant's scene, built by ``stewart_platform.scene_dict`` and edited."""
    kind = "bars" if v.legs == "bar" else "frame"
    base = {"key": v.key, "kind": kind, "elements": v.elements, "dt": v.dt}
    if tolerance is not None:
        base["tolerance"] = tolerance
    data = sp.scene_dict(base, t_end)
    data["name"] = f"stewart_{kind}_{v.elements}x{v.order}"
    data["solver"].update(v.solver_overrides())
    if kind == "frame":
        for leg in sp.LEGS:
            data["members"][leg] = dict(data["members"][leg], order=v.order)
    return data


def _start(v: core.Variant, t_end: float, tolerance: float | None = None):
    model = compile_scene(scene_from_dict(scene_dict(v, t_end, tolerance), source=f"<{v.key}>"))
    obs = PlatformObserver(model, sp.PLATFORM)
    pos, quat = np.zeros(3), np.zeros(4)

    def observe(sim: Simulator) -> np.ndarray:
        obs(sim.state.q, pos, quat)
        return np.concatenate([pos, quat])
    return (lambda: sp._start(model)), observe


def pose_errors(samples: dict[int, np.ndarray], ref: np.ndarray, t_end: float) -> tuple[float, float, float]:
    """(max centroid distance (m), max orientation angle (rad), centroid distance at the last mark)
    of pose samples (mark index → (7,): p, q) against the reference rows (t, p, q); NaN when a mark
    of 0–t_end is missing (the run did not complete)."""
    dp, da = [], []
    for r in ref[ref[:, 0] <= t_end + 1e-9]:
        k = int(round(r[0] / MARK))
        if k not in samples:
            return math.nan, math.nan, math.nan
        s = samples[k]
        dp.append(float(np.linalg.norm(s[:3] - r[1:4])))
        da.append(sp._quat_angle(s[3:], r[4:]))
    return max(dp), max(da), dp[-1]


def make_reference() -> Path:
    """Run the converged reference and store its platform pose (t, p, q) at the marks."""
    start, observe = _start(FINE, UNTIL, FINE_TOLERANCE)
    timed = core.timed_run(start, UNTIL, MARK, observe, budget_s=0, max_repeats=1)
    if not timed.completed:
        raise RuntimeError(f"the Stewart reference run failed: {timed.message}")
    ks = sorted(timed.samples)
    data = np.array([[k * MARK, *timed.samples[k]] for k in ks])
    core.write_reference(REFERENCE, {
        "case": "Stewart platform twin (SPEC §6.1), appendix trajectory, scenes/stewart_platform.yaml",
        "model": f"flexmb frame legs, {FINE.elements} cubic el./leg, gen-α ρ∞ = {FINE.rho_inf:g}, "
                 f"{FINE.newton} Newton, Δt = {FINE.dt:g} s, Newton tolerance {FINE_TOLERANCE:g}",
        "quantity": "platform centroid (m) and orientation quaternion (w, x, y, z) at the marks",
        "generated_by": "flexmb bench --case stewart --make-reference",
        "wall_s": f"{timed.wall:.1f}"}, ["t", "px", "py", "pz", "qw", "qx", "qy", "qz"], data)
    return REFERENCE


def _line(r: dict) -> str:
    return (f"  {r['code']:10s} {r['family']:44s} Δt {r['dt']:<8.3g} {r['steps_per_s']:8.0f} steps/s  "
            f"RTF {r['rtf']:7.2f}  error {r['error']:.2e} m / {r['error_orientation_rad']:.2e} rad"
            + ("" if r["completed"] else f"  FAILED: {r['note']}"))


def context(quick: bool) -> dict:
    """What every run compares with: the stored reference poses (t, p, q)."""
    return {"ref": core.read_reference(REFERENCE)[2]}


def variant_row(v: core.Variant, quick: bool, ctx: dict, *, budget_s: float, max_repeats: int) -> dict:
    """One variant's CSV row."""
    t_end = until(quick)
    start, observe = _start(v, t_end)
    timed = core.timed_run(start, t_end, MARK, observe, budget_s=budget_s, max_repeats=max_repeats)
    ep, ea, ef = pose_errors(timed.samples, ctx["ref"], t_end)
    return core.row(v, **core.timing_columns(timed, t_end), error=ep, error_orientation_rad=ea, error_final=ef)


def run(quick: bool, *, budget_s: float, max_repeats: int, log=print, client=None) -> list[dict]:
    """Every variant of the sweep as a CSV row (on Dask with a ``client``, :func:`core.run_variants`)."""
    return core.run_variants(NAME, variants(quick), quick, context(quick), budget_s=budget_s,
                             max_repeats=max_repeats, log=log, line=_line, client=client)


# -- peers ------------------------------------------------------------------------------------------
def peer_plan(quick: bool) -> dict[str, list[dict]]:
    if quick:
        return {"exudyn_stewart": [dict(case="ancf1", dt=2e-3)], "mujoco_stewart": [dict(dt=1e-3)]}
    return {"exudyn_stewart": [dict(case="ancf1", dt=dt) for dt in (4e-3, 2e-3, 1e-3)] + [dict(case="ancf4", dt=1e-3)],
            "mujoco_stewart": [dict(dt=dt) for dt in (5e-3, 2e-3, 1e-3, 5e-4)]}


def _exudyn_history(p: dict) -> np.ndarray:
    """Exudyn's 10 ms pose marks as rows (t, p, q)."""
    return np.column_stack([p["_marks"] * 0.01, p["_pos"], p["_quat"]])


def run_peers(quick: bool, *, repeats: int, log=print) -> tuple[list[dict], list[str]]:
    """Installed peers on the Stewart twin; returns rows and notes on what was skipped."""
    import importlib

    _, _, ref = core.read_reference(REFERENCE)
    t_end = until(quick)
    rows, notes = [], []
    for name, plan in peer_plan(quick).items():
        mod = importlib.import_module(f"benchmarks.peers.{name}")
        if not mod.available():
            notes.append(f"{name}: {getattr(mod, 'PACKAGE', name.split('_')[0])} is not installed (optional peer), skipped")
            continue
        for kw in plan:
            if name == "exudyn_stewart":
                p = mod.run(kw["case"], kw["dt"], t_end, repeats=min(repeats, 2))     # 3–10 s per 20 s run
                hist = _exudyn_history(p)
                family = f"Exudyn ANCF cable legs, {p['elements_per_leg']} el./leg, gen-α ρ∞=0.9"
                code, integ = p["label"].split(",")[0].replace("Exudyn ", "exudyn "), "generalized_alpha"
            else:
                p = mod.run(kw["dt"], t_end, repeats=repeats, mark=MARK)
                hist, family, code, integ = p["history"], p["family"], p["code"], p["integrator"]
            ok = bool(p["converged"])
            samples = {int(round(h[0] / MARK)): np.asarray(h[1:]) for h in hist
                       if abs(h[0] / MARK - round(h[0] / MARK)) < 1e-6}
            ep, ea, ef = pose_errors(samples, ref, t_end) if ok else (math.nan,) * 3
            r = core.row(case=NAME, code=code, family=family, legs="ANCF cable" if name == "exudyn_stewart" else "rigid",
                         elements=p.get("elements_per_leg", ""), integrator=integ, dt=kw["dt"], sim_time_s=t_end,
                         steps=p["steps"], completed=ok, t_reached_s=p["t_reached"], repeats=len(p["walls_s"]),
                         wall_s=p["wall_time_s"], wall_min_s=min(p["walls_s"]), wall_per_sim_s=p["wall_time_s"] / t_end if ok else math.nan,
                         rtf=p["rtf"], steps_per_s=p["steps_per_s"],
                         newton_iterations_mean=p.get("newton_iterations_mean", math.nan),
                         error=ep, error_orientation_rad=ea, error_final=ef, note=p.get("note", ""))
            rows.append(r)
            log(_line(r))
    return rows, notes


# -- report ----------------------------------------------------------------------------------------
PANELS = [("error", "max |platform centroid − converged reference| (m)"),
          ("error_orientation_rad", "max platform orientation deviation (rad)")]
TARGET = (1e-4, "SPEC §8 goal 1e-4 m")


def report_spec() -> dict:
    return {"errors": "**orientation** = max rotation angle between the platform orientations (rad); "
                      "**final** = centroid distance at the last mark (m). Peers: Exudyn (ANCF cable legs, rigid "
                      "platform) and MuJoCo (rigid legs with an axial servo spring, soft constraints) model the "
                      "same mechanism differently: their error holds that model difference "
                      "(benchmarks/peers/README.md).",
            "ratios": [("error", (1e-3, 1e-4, 1e-5, 1e-6), " m"), ("error", (1e-4, 1e-5, 1e-6), " m", 1e-3)],
            "columns": [("error", "pose error (m)"), ("error_orientation_rad", "orientation (rad)"),
                        ("error_final", "final (m)")]}
