"""Spin-up maneuver (Simo & Vu-Quoc 1986; SPEC §7.6): a 10 m beam spun up to 6 rad/s, 30 s.

flexmb runs ``scenes/spin_up.yaml`` (members and solver edited per variant). There is no closed form
for the history, so

* ``error`` — max over the 0.2 s marks of |tip(t) − tip_ref(t)| / L over 0–T, tip_ref the stored
  fine run ``benchmarks/reference/spin_up.csv`` (10 quartic el., Δt = 1.25 ms, full Newton,
  tolerance 1e-11). The tip travels a circle of radius 10 m: a phase lag shows as a position error.
* ``error_final`` — |tip(T) − tip_ref(T)| / L.

No peer runs this case (none of the three has a prescribed rotating clamp in the modules here).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene.loader import parse_yaml, scene_from_dict
from flexmb_core.simulator import Simulator

from . import core

NAME = "spin_up"
TITLE = "Spin-up maneuver (SPEC §7.6)"
SCENE = core.ROOT / "scenes" / "spin_up.yaml"
REFERENCE = core.REFERENCE_DIR / "spin_up.csv"
MARK = 0.2                   # s; a multiple of every Δt of the sweep
UNTIL = 30.0                 # s
UNTIL_QUICK = 6.0            # s; --quick: the first 6 s of the spin-up
L = 10.0
ERROR_UNIT = "1/L"
ERROR_MEASURE = "max over 0.2 s marks of |tip − fine run| / L"
FINE = core.Variant(NAME, dt=1.25e-3, elements=10, order=4, rho_inf=0.8, newton="full")
FINE_TOLERANCE = 1e-11
BASE = dict(elements=5, newton="full")          # the scene's: 5 cubic el., gen-α ρ∞ = 0.8, full Newton


def variants(quick: bool) -> list[core.Variant]:
    """The sweep: families (mesh, order, integrator, Newton) × Δt."""
    if quick:
        return core.sweep(NAME, [BASE], (0.04, 0.02, 0.01))
    dts = (0.04, 0.02, 0.01)
    fams = [dict(BASE, elements=n) for n in (3, 5, 10)]                                  # 0–2
    fams += [dict(BASE, elements=10, order=2), dict(BASE, elements=3, order=4)]          # 3–4
    fams += [dict(BASE, integrator="newmark")]                                           # 5
    fams += [dict(BASE, rho_inf=r) for r in (0.5, 0.9)]                                 # 6–7
    fams += [dict(BASE, newton="modified")]                                              # 8
    per = {i: dts for i in range(len(fams))}
    per[1] = dts + (0.005,)
    per.update({i: (0.02, 0.01) for i in (3, 4, 6, 7, 8)})
    per[5] = (0.02, 0.01)                 # trapezoidal: fails at 0.02, ~75 Newton it./step at 0.01 (minutes)
    return core.sweep(NAME, fams, per)


def until(quick: bool) -> float:
    return UNTIL_QUICK if quick else UNTIL


def scene_dict(v: core.Variant) -> dict:
    data = copy.deepcopy(parse_yaml(SCENE.read_text()))
    data["members"]["beam"] = dict(data["members"]["beam"], elements=v.elements, order=v.order)
    data["name"] = f"spin_up_{v.elements}x{v.order}"
    return data


def _start(v: core.Variant, t_end: float, tolerance: float | None = None):
    overrides = dict(v.solver_overrides(), until=t_end)
    if tolerance is not None:
        overrides["tolerance"] = tolerance
    model = compile_scene(scene_from_dict(scene_dict(v), source=f"<{v.key}>", overrides=overrides))

    def start() -> Simulator:
        sim = Simulator(model)
        sim.warmup()
        sim.initialize()
        return sim
    return start


def _tip(sim: Simulator) -> np.ndarray:
    return np.asarray(sim.outputs()["tip"], dtype=float)


def make_reference() -> Path:
    """Run the fine reference and store its tip history (t, x, y, z) at the marks."""
    timed = core.timed_run(_start(FINE, UNTIL, FINE_TOLERANCE), UNTIL, MARK, _tip, budget_s=0, max_repeats=1)
    if not timed.completed:
        raise RuntimeError(f"the spin-up reference run failed: {timed.message}")
    ks = sorted(timed.samples)
    data = np.array([[k * MARK, *timed.samples[k]] for k in ks])
    core.write_reference(REFERENCE, {
        "case": "spin-up maneuver (SPEC §7.6), scenes/spin_up.yaml",
        "model": f"flexmb {FINE.family}, Δt = {FINE.dt:g} s, Newton tolerance {FINE_TOLERANCE:g}",
        "quantity": "tip position (m) at the marks",
        "generated_by": "flexmb bench --case spin_up --make-reference",
        "wall_s": f"{timed.wall:.1f}"}, ["t", "x", "y", "z"], data)
    return REFERENCE


def context(quick: bool) -> dict:
    """What every run compares with: the stored fine run (t, x, y, z)."""
    return {"ref": core.read_reference(REFERENCE)[2]}


def variant_row(v: core.Variant, quick: bool, ctx: dict, *, budget_s: float, max_repeats: int) -> dict:
    """One variant's CSV row."""
    ref, t_end = ctx["ref"], until(quick)
    timed = core.timed_run(_start(v, t_end), t_end, MARK, _tip, budget_s=budget_s, max_repeats=max_repeats)
    err, final, _ = core.history_error(timed.samples, ref[:, 0], ref[:, 1:], MARK, t_end, L)
    return core.row(v, **core.timing_columns(timed, t_end), error=err, error_final=final)


def _line(r: dict) -> str:
    return (f"  {r['code']:10s} {r['family']:44s} Δt {r['dt']:<8.3g} {r['steps_per_s']:8.0f} steps/s  "
            f"wall/sim-s {r['wall_per_sim_s']:8.3g}  error {r['error']:.2e}"
            + ("" if r["completed"] else f"  FAILED at t = {r['t_reached_s']:.3f} s: {r['note']}"))


def run(quick: bool, *, budget_s: float, max_repeats: int, log=print, client=None) -> list[dict]:
    """Every variant of the sweep as a CSV row (on Dask with a ``client``, :func:`core.run_variants`)."""
    return core.run_variants(NAME, variants(quick), quick, context(quick), budget_s=budget_s,
                             max_repeats=max_repeats, log=log, line=_line, client=client)


def run_peers(quick: bool, *, repeats: int, log=print) -> tuple[list[dict], list[str]]:
    return [], []


# -- report ----------------------------------------------------------------------------------------
PANELS = [("error", "max |tip − fine run| / L over the run")]
TARGET = None


def report_spec() -> dict:
    return {"errors": "**error_final** = |tip(T) − fine run| / L at the last mark. No peer runs this case.",
            "ratios": [], "columns": [("error", "error /L"), ("error_final", "final /L")]}
