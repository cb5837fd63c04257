"""B1 (SPEC §8): large-deflection steel cantilever, k = PL²/EI = 2, 2 s, light mass damping.

flexmb runs ``scenes/cantilever_b1.yaml`` (members and solver edited per variant). Errors, all
divided by L:

* ``error`` — max over the 20 ms marks of |tip(t) − tip_ref(t)| over 0–2 s, tip_ref the stored fine
  run ``benchmarks/reference/b1.csv`` (16 cubic el., Δt = 1/16 ms, full Newton, tolerance 1e-12).
  This is the dynamic error: it falls with Δt at order 2 and with the mesh; for a peer it also
  holds the model difference (another beam theory, another damping form).
* ``error_final`` — |tip(2 s) − the converged solution of the code's own continuum|: for flexmb the
  static 32-element Saint-Venant–Kirchhoff solution (``b1_cantilever.converged_reference``); for a
  peer the closed form of its continuum (extensible elastica with its EA, GA; inextensible for
  MuJoCo's rod). At 2 s the tip has settled to ~4e-7·L, which floors this error.
* ``error_closed_form`` — |tip(2 s) − the inextensible elastica (0.839358, −0.493457)|: SPEC §8's B1
  error, the same yardstick for every code (flexmb's SVK law sits 4e-5·L from it, see README).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene.loader import parse_yaml, scene_from_dict
from flexmb_core.simulator import Simulator
from flexmb_core.verification.analytic import extensible_elastica_cantilever

from benchmarks import b1_cantilever as b1c

from . import core

NAME = "b1"
TITLE = "B1 cantilever (SPEC §8), 2 s"
SCENE = core.ROOT / "scenes" / "cantilever_b1.yaml"
REFERENCE = core.REFERENCE_DIR / "b1.csv"
MARK = 0.02                  # s; a multiple of every Δt of the sweep
UNTIL = 2.0                  # s
L = b1c.L
ERROR_UNIT = "1/L"
ERROR_MEASURE = "max over 20 ms marks of |tip − fine run| / L, 0–2 s"
FINE = core.Variant(NAME, dt=6.25e-5, elements=16, order=3, newton="full")
FINE_TOLERANCE = 1e-12


def variants(quick: bool) -> list[core.Variant]:
    """The sweep: families (mesh, order, integrator, Newton) × Δt."""
    ms = 1e-3
    if quick:
        return core.sweep(NAME, [dict(elements=4), dict(elements=8)], (4 * ms, 2 * ms, 1 * ms)) + \
            core.sweep(NAME, [dict(elements=4, integrator="newmark"), dict(elements=4, newton="full")], (1 * ms,))
    dts = (4 * ms, 2 * ms, 1 * ms, 0.5 * ms, 0.25 * ms)
    fams = [dict(elements=n) for n in (2, 4, 8, 16)]                                     # 0–3
    fams += [dict(elements=n, order=2) for n in (4, 8, 16)]                              # 4–6
    fams += [dict(elements=n, order=4) for n in (2, 4)]                                  # 7–8
    fams += [dict(elements=4, integrator="newmark")]                                     # 9
    fams += [dict(elements=4, rho_inf=r) for r in (0.5, 1.0)]                            # 10–11
    fams += [dict(elements=4, newton="full")]                                            # 12
    per = {i: dts for i in range(len(fams))}
    per.update({i: dts[1:4] for i in (4, 5, 6, 7, 8)})
    per[3] = dts[:4]
    return core.sweep(NAME, fams, per)


def scene_dict(v: core.Variant) -> dict:
    data = copy.deepcopy(parse_yaml(SCENE.read_text()))
    data["members"]["beam"] = dict(data["members"]["beam"], elements=v.elements, order=v.order)
    data["name"] = f"b1_{v.elements}x{v.order}"
    return data


def _start(v: core.Variant, until: float, tolerance: float | None = None):
    overrides = dict(v.solver_overrides(), until=until)
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


def closed_forms() -> dict[str, np.ndarray]:
    """Tip (x, 0, z) of: the converged flexmb continuum (static, 32 el.), the inextensible elastica,
    the extensible elastica with flexmb's EA and k_s·G·A, and with GA → ∞ (the cable's)."""
    E, nu, A, I, P = b1c.E, b1c.NU, b1c.AREA, b1c.INERTIA, b1c.P
    ks = 6 * (1 + nu) / (7 + 6 * nu)                              # circle, as the frame element
    G = E / (2 * (1 + nu))

    def ext(ga: float) -> np.ndarray:
        e = extensible_elastica_cantilever(L, E * I, E * A, ga, P)
        return np.array([e["x_tip"], 0.0, e["z_tip"]])
    return {"flexmb_converged": np.asarray(b1c.converged_reference(), dtype=float),
            "inextensible": np.array([b1c.INEXTENSIBLE[0], 0.0, b1c.INEXTENSIBLE[1]]) * L,
            "extensible_flexmb": ext(ks * G * A),
            "extensible_shear_rigid": ext(1e6 * E * A),
            "extensible_pyelastica": ext(27.0 / 28.0 * G * A)}


def make_reference() -> Path:
    """Run the fine reference and store its tip history (t, x, y, z) at the marks."""
    timed = core.timed_run(_start(FINE, UNTIL, FINE_TOLERANCE), UNTIL, MARK, _tip, budget_s=0, max_repeats=1)
    if not timed.completed:
        raise RuntimeError(f"the B1 reference run failed: {timed.message}")
    ks = sorted(timed.samples)
    data = np.array([[k * MARK, *timed.samples[k]] for k in ks])
    core.write_reference(REFERENCE, {
        "case": "B1 cantilever (SPEC §8), scenes/cantilever_b1.yaml",
        "model": f"flexmb {FINE.family}, Δt = {FINE.dt:g} s, Newton tolerance {FINE_TOLERANCE:g}",
        "quantity": "tip position (m) at the marks",
        "generated_by": "flexmb bench --case b1 --make-reference",
        "wall_s": f"{timed.wall:.1f}"}, ["t", "x", "y", "z"], data)
    return REFERENCE


def context(quick: bool) -> dict:
    """What every run compares with: the stored fine run (t, x, y, z) and the closed forms."""
    return {"ref": core.read_reference(REFERENCE)[2], "forms": closed_forms()}


def variant_row(v: core.Variant, quick: bool, ctx: dict, *, budget_s: float, max_repeats: int) -> dict:
    """One variant's CSV row."""
    ref, forms = ctx["ref"], ctx["forms"]
    timed = core.timed_run(_start(v, UNTIL), UNTIL, MARK, _tip, budget_s=budget_s, max_repeats=max_repeats)
    err, _, _ = core.history_error(timed.samples, ref[:, 0], ref[:, 1:], MARK, UNTIL, L)
    r = core.row(v, **core.timing_columns(timed, UNTIL), error=err)
    if timed.completed:
        tip = timed.samples[max(timed.samples)]
        r.update(error_final=float(np.linalg.norm(tip - forms["flexmb_converged"])) / L,
                 error_closed_form=float(np.linalg.norm(tip - forms["inextensible"])) / L)
    return r


def run(quick: bool, *, budget_s: float, max_repeats: int, log=print, client=None) -> list[dict]:
    """Every variant of the sweep as a CSV row (on Dask with a ``client``, :func:`core.run_variants`)."""
    return core.run_variants(NAME, variants(quick), quick, context(quick), budget_s=budget_s,
                             max_repeats=max_repeats, log=log, line=_line, client=client)


def _line(r: dict) -> str:
    return (f"  {r['code']:10s} {r['family']:44s} Δt {r['dt']:<8.3g} {r['steps_per_s']:8.0f} steps/s  "
            f"wall/sim-s {r['wall_per_sim_s']:8.3g}  error {r['error']:.2e}  final {r['error_final']:.2e}"
            + ("" if r["completed"] else f"  FAILED: {r['note']}"))


# -- peers ------------------------------------------------------------------------------------------
def peer_plan(quick: bool) -> dict[str, list[dict]]:
    """Peer runs: module name → keyword arguments of its ``run_b1``."""
    if quick:
        return {"exudyn_b1": [dict(n_elements=n, dt=1e-3) for n in (8, 16)],
                "mujoco_b1": [dict(n_elements=16, dt=1e-3)],
                "pyelastica_b1": []}
    return {"exudyn_b1": [dict(n_elements=n, dt=1e-3) for n in (4, 8, 16, 32)]
            + [dict(n_elements=16, dt=dt) for dt in (4e-3, 2e-3, 5e-4)]
            + [dict(n_elements=64, dt=1e-4)],
            "mujoco_b1": [dict(n_elements=n, dt=1e-3) for n in (8, 16, 32, 64)]
            + [dict(n_elements=64, dt=1e-4), dict(n_elements=16, dt=1e-2), dict(n_elements=16, dt=1e-4),
               dict(n_elements=16, dt=1e-3, clamp="grid"), dict(n_elements=64, dt=1e-4, clamp="grid"),
               dict(n_elements=16, dt=1e-2, clamp="grid", solimp=None),
               dict(n_elements=64, dt=1e-4, clamp="grid", solimp=None)],
            "pyelastica_b1": [dict(n_elements=n, dt=1.5e-6) for n in (8, 16)]}


def peer_row(name: str, p: dict, forms: dict[str, np.ndarray], ref: np.ndarray) -> dict:
    """A CSV row from a peer's return dict (``history``: (n, 4) t, x, y, z at the marks)."""
    own = {"exudyn_b1": "extensible_shear_rigid", "mujoco_b1": "inextensible",
           "pyelastica_b1": "extensible_pyelastica"}[name]
    ok = bool(p["converged"])
    r = core.row(case=NAME, code=p["code"], family=p["family"], elements=p["n_elements"],
                 integrator=p.get("integrator", ""), dt=p["dt"], sim_time_s=UNTIL, steps=p["steps"], completed=ok,
                 t_reached_s=p["t_reached"], repeats=len(p.get("wall_times_s", [1])), wall_s=p["wall_time_s"],
                 wall_min_s=min(p.get("wall_times_s", [p["wall_time_s"]])),
                 wall_per_sim_s=p["wall_time_s"] / UNTIL if ok else math.nan, rtf=p["rtf"],
                 steps_per_s=p["steps_per_s"], newton_iterations_mean=p.get("newton_iterations_mean", math.nan),
                 note=p.get("note", ""))
    if ok:
        h = np.asarray(p["history"])
        samples = {int(round(t / MARK)): x for t, *x in h}
        samples = {k: np.asarray(x) for k, x in samples.items()}
        r["error"], _, _ = core.history_error(samples, ref[:, 0], ref[:, 1:], MARK, UNTIL, L)
        tip = np.array([p["tip"][0], 0.0, p["tip"][1]])
        r["error_final"] = float(np.linalg.norm(tip - forms[own])) / L
        r["error_closed_form"] = float(np.linalg.norm(tip - forms["inextensible"])) / L
    return r


def run_peers(quick: bool, *, repeats: int, log=print) -> tuple[list[dict], list[str]]:
    """Installed peers on B1; returns rows and notes on what was skipped."""
    import importlib

    _, _, ref = core.read_reference(REFERENCE)
    forms = closed_forms()
    rows, notes = [], []
    for name, plan in peer_plan(quick).items():
        mod = importlib.import_module(f"benchmarks.peers.{name}")
        if not mod.available():
            notes.append(f"{name}: {mod.PACKAGE} is not installed (optional peer), skipped")
            continue
        if not plan:
            notes.append(f"{name}: skipped in --quick (an explicit rod at Δt ≈ 1.5 µs needs ~70 s per run)")
            continue
        for kw in plan:
            p = mod.run_b1(**kw, t_end=UNTIL, repeats=repeats if kw.get("dt", 1) >= 5e-4 else 1,
                           history_period=MARK)
            r = peer_row(name, p, forms, ref)
            rows.append(r)
            log(_line(r))
    return rows, notes


# -- report ----------------------------------------------------------------------------------------
PANELS = [("error", "max |tip − fine run| / L over 0–2 s (dynamic error)"),
          ("error_final", "|tip(2 s) − converged solution of the code's own continuum| / L")]
TARGET = (1e-5, "SPEC §8 target 1e-5·L")


def report_spec() -> dict:
    return {"errors": "**error_final** = |tip(2 s) − the converged solution of the code's own continuum| / L "
                      "(flexmb: static Saint-Venant–Kirchhoff solution, 32 cubic el.; Exudyn: extensible elastica "
                      "with GA → ∞; PyElastica: extensible, shearable elastica with its GA = 27/28·G·A; MuJoCo: "
                      "inextensible elastica); **closed form** = |tip(2 s) − inextensible elastica (0.839358, "
                      "−0.493457)·L| / L, SPEC §8's B1 error (flexmb's SVK law is 4e-5·L from it: a model "
                      "difference, README).",
            "ratios": [("error", (1e-3, 1e-4, 1e-5, 1e-6), "·L"), ("error_final", (1e-3, 1e-4, 1e-5), "·L")],
            "columns": [("error", "error /L"), ("error_final", "final vs own continuum /L"),
                        ("error_closed_form", "final vs inext. elastica /L")]}
