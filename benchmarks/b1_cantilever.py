"""Benchmark B1 (SPEC §8): large-deflection steel cantilever, k = PL²/EI = 2, Δt = 1 ms, 2 s.

Reports steps/s, real-time factor and tip error for 2/4/8/16 cubic elements (and, with
``--quartic``, quartic ones), against
  * the converged reference of the same continuum (32 elements, static): the numerical error;
  * the inextensible and the extensible elastica: the model difference (SVK bending softening).
Peers (Exudyn ANCF) run in the same process when installed. Results: docs/benchmarks/b1.{md,json}.

``--profile`` instead writes docs/benchmarks/b1_profile.md: where the µs of a step of the numba
step go, 4 cubic elements, modified Newton, and the Newton work over the load ramp and after it.

    .venv/bin/python benchmarks/b1_cantilever.py [--repeats 3] [--meshes 2 4 8 16] [--quartic 2 3]
    .venv/bin/python benchmarks/b1_cantilever.py --profile
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import scene_from_dict  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402
from flexmb_core.verification.analytic import extensible_elastica_cantilever  # noqa: E402

E, NU, RHO, R, L = 200e9, 0.3, 7850.0, 0.005, 1.0
AREA, INERTIA = math.pi * R**2, math.pi * R**4 / 4
P = 2 * E * INERTIA / L**2
INEXTENSIBLE = (0.839358279175, -0.493457480397)


def scene(elements: int, *, analysis="dynamic", dt=1e-3, until=2.0, newton="full", order=3,
          tolerance: float = 1e-10) -> dict:
    return {
        "name": f"b1_{elements}",
        "materials": {"steel": {"E": E, "nu": NU, "rho": RHO}},
        "sections": {"rod": {"shape": "circle", "radius": R}},
        "nodes": {"root": [0, 0, 0], "tip": [L, 0, 0]},
        "members": {"beam": {"kind": "frame", "from": "root", "to": "tip", "elements": elements, "order": order,
                             "material": "steel", "section": "rod"}},
        "supports": [{"node": "root", "type": "clamp"}],
        "loads": {"forces": {"p": {"node": "tip", "force": [0, 0, -P],
                                   "signal": {"kind": "ramp", "duration": 0.5 if analysis == "dynamic" else 1.0,
                                              "shape": "smooth"}}}},
        "damping": {"mass_proportional": 10.0},
        "solver": {"analysis": analysis, "integrator": "generalized_alpha", "rho_inf": 0.8, "dt": dt,
                   "until": until, "tolerance": tolerance, "newton": newton},
        "outputs": {"tip": {"kind": "node_position", "node": "tip"}},
    }


def converged_reference() -> np.ndarray:
    sim = Simulator(compile_scene(scene_from_dict(scene(32, analysis="static", dt=0.25, until=1.0))))
    sim.initialize()
    sim.run(1.0)
    return np.array(sim.outputs()["tip"])


def run_flexmb(elements: int, repeats: int, newton: str, order: int = 3, tolerance: float = 1e-10) -> dict:
    walls, sim = [], None
    for _ in range(repeats):
        sim = Simulator(compile_scene(scene_from_dict(scene(elements, newton=newton, order=order,
                                                            tolerance=tolerance))))
        sim.warmup()
        sim.initialize()
        t0 = time.perf_counter()
        sim.run(2.0)
        walls.append(time.perf_counter() - t0)
    s = sim.summary()
    wall = statistics.median(walls)
    kind = {3: "cubic", 4: "quartic"}.get(order, f"order {order}")
    return {"code": f"flexmb ({newton} Newton)", "model": f"{elements} {kind} frame el. (reduced axial rule)",
            "n_elements": elements, "order": order, "newton": newton, "tolerance": tolerance,
            "dt": 1e-3, "steps": s["steps"], "wall_time_s": wall, "steps_per_s": s["steps"] / wall,
            "wall_times_s": walls, "rtf": 2.0 / wall, "newton_iterations_mean": s["newton_iterations_mean"],
            "tangent_updates": sim._dynamic.tangent_updates,
            "tip": [sim.outputs()["tip"][0], sim.outputs()["tip"][2]]}


# ------------------------------------------------------------------------------------------------
# profile
# ------------------------------------------------------------------------------------------------
def _component_costs(model) -> dict:
    """µs per call of each kernel of the numba step, timed inside numba (no dispatch), at the state
    after 0.6 s."""
    from numba import njit

    from flexmb_core.integrators.energy import _energies
    from flexmb_core.integrators.fused import inertial_residual
    from flexmb_core.kernels.frame3d import frame_group
    from flexmb_core.solvers.banded import STATIC_PIVOT, _factor_kernel, _solve_kernel

    sim = Simulator(model)
    sim.warmup()
    sim.initialize()
    sim.run(0.6)
    integ, ws, m, g = sim._dynamic, sim.ws, model, model.frame_groups[0]
    q, lam, lr = sim.state.q.copy(), np.ones(0), np.zeros(0)
    n = m.ndof
    iv, wb, rf = np.zeros((7, n)), np.zeros(n), np.zeros(m.nsys)

    @njit
    def rep_fg(k, want_k, q, v, edofs, dax, dsec, w, nsec, mat, act, lam, lr, smap, r, kd, *sc):
        for _ in range(k):
            frame_group(q, v, edofs, dax, dsec, w, nsec, mat, act, lam, lr, 0.0, smap, want_k, False, r, kd, *sc)

    @njit
    def rep_ir(k, q, qh, at, an, vn, mb, mi, mj, mv, r, f, free_pos, wb, rf, gp):
        s = 0.0
        for _ in range(k):
            s += inertial_residual(q, qh, at, an, vn, 1e6, 0.1, 0.2, 0.6, 1e-3, 10.0, mb, mi, mj, mv, r, f, free_pos,
                                   wb, rf, False, gp)[0]
        return s

    @njit
    def rep_solve(k, rf, perm, base, a, b, c, d, e, f, env, idg, work, out):
        for _ in range(k):
            _solve_kernel(rf, perm, base, a, b, c, d, e, f, env, idg, work, out)

    @njit
    def rep_factor(k, kd, mk, coef, slot, acc, zs, base, a, b, c, d, e, f, blk, env, idg, ptol, spiv, stats):
        for _ in range(k):
            _factor_kernel(kd, mk, coef, slot, acc, zs, base, a, b, c, d, e, f, blk, env, idg, ptol, spiv, stats, 0)

    @njit
    def rep_en(k, mb, mi, mj, mv, v, q, q0, gr):
        s = 0.0
        for _ in range(k):
            s += _energies(mb, mi, mj, mv, v, q, q0, gr)[0]
        return s

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from step_profile import best_us as best

    ga = (q, ws.zero_v, g.edofs, g.dax, g.dsec, g.w, g.nsec, g.mat, g.act, lam, lr, g.smap, ws.r, ws.kdata,
          *ws.frame_scratch[0], *ws.frame_structure[0])
    sky = integ.lu.skyline
    return {"element kernels, residual": best(rep_fg, False, *ga),
            "element kernels, residual + tangent": best(rep_fg, True, *ga, k=100),
            "inertial residual M(a + c_m v)": best(rep_ir, q, iv[4], iv[3], iv[2], iv[1], *integ._mass_blocks, ws.r,
                                                   ws.f_ext, m.free_index, wb, rf, iv[6]),
            "LU solve": best(rep_solve, rf, sky.perm, sky._base, *sky._lrun, *sky._urun, sky._env, sky._inv_diag,
                             sky._work, np.zeros(m.nsys)),
            "LU factor": best(rep_factor, ws.kdata, sky._writable(m.mass_kdata), 1e6, sky._slot, sky._accumulate,
                              sky._zero_slots, sky._base, *sky._lrun, *sky._urun, sky._blk_ptr, sky._env,
                              sky._inv_diag, sky.pivot_tol, STATIC_PIVOT, sky._stats, k=100),
            "energies": best(rep_en, *integ._mass_blocks, sim.state.v, q, m.q0, m.gravity_vector)}


def _profile_numba(model, until: float) -> tuple[float, float, dict]:
    """Per-step µs of the numba step: total, and inside the one kernel call (dispatch included),
    best of 3 runs each; Newton iterations and tangent refreshes per step over the load ramp
    (t ≤ 0.5 s) and after it."""
    import flexmb_core.integrators.fast as F
    kernels = {"model_step": F.model_step, "model_steps": F.model_steps}   # one step; a steady stretch
    spent = [0]

    def timed(kern):
        def w(*a):
            t0 = time.perf_counter_ns()
            r = kern(*a)
            spent[0] += time.perf_counter_ns() - t0
            return r
        return w
    totals, inside = [], []
    for wrapped in (False, True) * 3:
        for name, kern in kernels.items():
            setattr(F, name, timed(kern) if wrapped else kern)
        spent[0] = 0
        try:
            sim = Simulator(model)
            sim.warmup()
            sim.initialize()
            t0 = time.perf_counter()
            sim.run(until)
            wall = time.perf_counter() - t0
        finally:
            for name, kern in kernels.items():
                setattr(F, name, kern)
        (inside if wrapped else totals).append((wall / sim.stats.steps * 1e6, spent[0] / sim.stats.steps / 1000))
    counts = {}
    for _ in range(3):          # the phases' walls: best of 3 runs
        sim = Simulator(model)
        sim.warmup()
        sim.initialize()
        for phase, end in (("ramp", 0.5), ("after", until)):
            it0, tan0, steps0 = sim.stats.iterations_total, sim._dynamic.tangent_updates, sim.stats.steps
            t0 = time.perf_counter()
            sim.run(end)
            wall = time.perf_counter() - t0
            steps = sim.stats.steps - steps0
            us = min(wall / steps * 1e6, counts.get(phase, {}).get("us", math.inf))
            counts[phase] = {"iterations": (sim.stats.iterations_total - it0) / steps,
                             "tangents": (sim._dynamic.tangent_updates - tan0) / steps, "steps": steps, "us": us}
    counts["all"] = {"iterations": sim.stats.iterations_total / sim.stats.steps,
                     "tangents": sim._dynamic.tangent_updates / sim.stats.steps, "steps": sim.stats.steps}
    return min(t for t, _ in totals), min(k for _, k in inside), counts


def write_profile(out: Path, elements: int = 4, until: float = 2.0, tolerance: float = 1e-8) -> None:
    model = compile_scene(scene_from_dict(scene(elements, newton="modified", tolerance=tolerance)))
    total, kernel, cnt = _profile_numba(model, until)
    comp = _component_costs(model)
    date = time.strftime("%Y-%m-%d %H:%M:%S")
    lines = [f"# B1 profile — {elements} cubic elements, modified Newton, tolerance {tolerance:.0e}, Δt = 1 ms, 2 s",
             "",
             f"Generated by `benchmarks/b1_cantilever.py --profile` on {date} ({platform.platform()}, "
             f"{os.cpu_count()} cores, one used). The machine is shared and its speed drifts by tens of per cent "
             "over seconds: totals are the best of 3 runs; the parts inside the kernel are the kernels timed in "
             "numba loops (no dispatch) × their calls per step, so they add up only approximately.", "",
             f"**{total:.1f} µs/step ({1e6 / total:.0f} steps/s), of which {kernel:.1f} µs inside the numba calls "
             "and the rest the Python around them.** `Simulator.run` runs the steps in batches, one numba call "
             "each (`flexmb_core/integrators/fast.py: model_steps`): 256 at a time, their loads formed beforehand "
             "in Python, while the load ramps; all the rest at once after it. Before (the same run at tolerance "
             "1e-10, one call per step throughout): 36.3 µs/step (`git show 16d93fc:docs/benchmarks/b1_profile.md`). "
             "Before the numba step (the Python Newton loop, issue 7 item B): 195 µs "
             "(`git show 2c65b06:docs/benchmarks/b1_profile.md`).", "",
             "## Newton work per step", "",
             "| phase | steps | Newton iterations/step | tangent refreshes/step | µs/step (best of 3) |",
             "|---|---|---|---|---|"]
    for phase, label in (("ramp", "load ramp, t ≤ 0.5 s"), ("after", "after the ramp"), ("all", "whole run")):
        c = cnt[phase]
        us = f"{c['us']:.1f}" if "us" in c else f"{total:.1f}"
        lines.append(f"| {label} | {c['steps']} | {c['iterations']:.2f} | {c['tangents']:.3f} | {us} |")
    its, tan = cnt["all"]["iterations"], cnt["all"]["tangents"]
    lines += ["", "## Where a step goes", "", "| part | calls/step | µs/call | µs/step |", "|---|---|---|---|"]
    rows = [("element kernels, residual", its - tan), ("element kernels, residual + tangent", tan),
            ("inertial residual M(a + c_m v)", its), ("LU solve", its), ("LU factor", tan), ("energies", 1.0)]
    est = 0.0
    for k, c in rows:
        us = comp[k] * c
        est += us
        lines.append(f"| {k} | {c:.3f} | {comp[k]:.2f} | {us:.1f} |")
    lines += [f"| rest of the kernel (predictor, rates, step guard, argument dispatch) | | | {kernel - est:.1f} |",
              f"| Python around the calls (the loads of each ramp step, `Simulator.run`, `DynamicIntegrator.steps`, "
              f"StepResult) | | | {total - kernel:.1f} |",
              f"| **total** | | | **{total:.1f}** |", "",
              "## What limits it now", "",
              f"- The tangent refreshes of the load ramp: {cnt['ramp']['tangents']:.2f} per step there (against "
              f"{cnt['after']['tangents']:.3f} after it), each an element tangent pass and a skyline LU "
              f"({comp['element kernels, residual + tangent'] + comp['LU factor']:.0f} µs). While the load ramps the "
              "stiff axial direction of each element turns with it, a one-step-old tangent contracts too slowly, "
              "and the modified-Newton rule refreshes it.",
              f"- The residual evaluations: {cnt['ramp']['iterations']:.2f} per step in the ramp, "
              f"{cnt['after']['iterations']:.2f} after it.",
              f"- The ramp itself: {cnt['ramp']['us']:.1f} µs per step against {cnt['after']['us']:.1f} after it, "
              f"so its quarter of the steps takes {cnt['ramp']['us'] * cnt['ramp']['steps'] / (total * cnt['all']['steps']) * 100:.0f} % "
              "of the run.",
              f"- The Python around the calls: {total - kernel:.1f} µs per step on average."]
    out.mkdir(parents=True, exist_ok=True)
    (out / "b1_profile.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"wrote {out / 'b1_profile.md'}")


def head_to_head(rounds: int, ref: np.ndarray) -> list[dict]:
    """flexmb (4 cubic, 2 quartic; modified Newton) and Exudyn (8, 16 ANCF el.), one run each per
    round, interleaved; medians of steps/s and of the per-round ratio to Exudyn 16 el."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from peers import exudyn_b1
    # Newton tolerance 1e-10 (the table above) and 1e-8 (the twins' scenes): the tip error is the
    # discretization's either way, the tighter tolerance costs ~0.7 iterations per step
    cases = [("flexmb, 4 cubic el., modified Newton", lambda: run_flexmb(4, 1, "modified", 3)),
             ("flexmb, 2 quartic el., modified Newton", lambda: run_flexmb(2, 1, "modified", 4)),
             ("flexmb, 4 cubic el., modified Newton, tol 1e-8", lambda: run_flexmb(4, 1, "modified", 3, 1e-8)),
             ("flexmb, 2 quartic el., modified Newton, tol 1e-8", lambda: run_flexmb(2, 1, "modified", 4, 1e-8)),
             ("Exudyn ANCF, 8 el.", lambda: exudyn_b1.run_b1(8, repeats=1)),
             ("Exudyn ANCF, 16 el.", lambda: exudyn_b1.run_b1(16, repeats=1))]
    speed: dict[str, list[float]] = {c: [] for c, _ in cases}
    ratio: dict[str, list[float]] = {c: [] for c, _ in cases}
    err: dict[str, tuple[float, str]] = {}
    for _ in range(rounds):
        got = {}
        for name, run in cases:
            r = run()
            got[name] = r["steps_per_s"]
            if "tip_error" in r:
                err[name] = (r["tip_error"], "vs inextensible elastica")
            else:
                err[name] = (float(np.hypot(*(np.array(r["tip"]) - ref[[0, 2]])) / L), "vs converged FE")
        for name in got:
            speed[name].append(got[name])
            ratio[name].append(got[name] / got["Exudyn ANCF, 16 el."])
    return [{"case": c, "steps_per_s": statistics.median(speed[c]), "ratio": statistics.median(ratio[c]),
             "error": err[c][0], "error_kind": err[c][1], "steps_per_s_all": speed[c]} for c, _ in cases]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--meshes", type=int, nargs="+", default=[2, 4, 8, 16], help="cubic elements")
    ap.add_argument("--quartic", type=int, nargs="*", default=[2, 3], help="quartic elements")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks"))
    ap.add_argument("--profile", action="store_true", help="write b1_profile.md instead")
    ap.add_argument("--rounds", type=int, default=7,
                    help="rounds of the interleaved head-to-head (flexmb and Exudyn alternately; 0: skip)")
    args = ap.parse_args()
    if args.profile:
        write_profile(Path(args.out))
        return 0

    ref = converged_reference()
    ext = extensible_elastica_cantilever(L, E * INERTIA, E * AREA,
                                         6 * (1 + NU) / (7 + 6 * NU) * E / (2 * (1 + NU)) * AREA, P)
    rows = []
    cases = [(n, 3, nw) for n in args.meshes for nw in ("full", "modified")]
    cases += [(n, 4, "modified") for n in args.quartic]
    for n, order, newton in cases:
        r = run_flexmb(n, args.repeats, newton, order)
        tip = np.array(r["tip"])
        r["error_vs_converged"] = float(np.hypot(*(tip - ref[[0, 2]])) / L)
        r["error_vs_inextensible_elastica"] = float(np.hypot(*(tip - INEXTENSIBLE)) / L)
        r["error_vs_extensible_elastica"] = float(np.hypot(tip[0] - ext["x_tip"], tip[1] - ext["z_tip"]) / L)
        rows.append(r)
        print(f"{r['code']:26s} {n:3d} el. p={order}: {r['steps_per_s']:9.0f} steps/s  RTF {r['rtf']:7.2f}  "
              f"err(conv) {r['error_vs_converged']:.1e}  err(inext) {r['error_vs_inextensible_elastica']:.1e}",
              flush=True)
    peers = []
    try:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from peers import exudyn_b1
        if exudyn_b1.available():
            for n in args.meshes:
                p = exudyn_b1.run_b1(n, repeats=args.repeats)
                peers.append(p)
                print(f"{p['code']} {n:3d} el.: {p['steps_per_s']:9.0f} steps/s  err(inext) {p['tip_error']:.1e}",
                      flush=True)
    except ImportError:
        pass

    h2h = head_to_head(args.rounds, ref) if args.rounds and peers else []

    meta = {"machine": platform.platform(), "python": platform.python_version(), "cpus": os.cpu_count(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S"), "converged_reference_tip": ref[[0, 2]].tolist(),
            "extensible_elastica_tip": [ext["x_tip"], ext["z_tip"]], "inextensible_elastica_tip": list(INEXTENSIBLE)}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "b1.json").write_text(json.dumps({"meta": meta, "flexmb": rows, "peers": peers, "head_to_head": h2h},
                                            indent=2) + "\n")
    lines = ["# B1 — large-deflection cantilever (k = 2), Δt = 1 ms, 2 s simulated", "",
             f"Generated by `benchmarks/b1_cantilever.py` on {meta['date']} ({meta['machine']}, "
             f"{meta['cpus']} cores, one used). Wall time = median of {args.repeats} runs, JIT warm-up excluded. "
             "flexmb: Newton tolerance 1e-10 (scaled increment); `Simulator.run` runs the numba step "
             "(`flexmb_core/integrators/fast.py`) in batches of steps, one call each — see `b1_profile.md`.", "",
             "| code | elements | order | steps/s | RTF | Newton it./step | tip error vs converged FE | "
             "vs inextensible elastica | vs extensible elastica |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['code']} | {r['n_elements']} | {r['order']} | {r['steps_per_s']:.0f} | {r['rtf']:.2f} | "
                     f"{r['newton_iterations_mean']:.2f} | {r['error_vs_converged']:.1e} | "
                     f"{r['error_vs_inextensible_elastica']:.1e} | {r['error_vs_extensible_elastica']:.1e} |")
    for p in peers:
        lines.append(f"| {p['code']} | {p['n_elements']} | 3 (Hermite) | {p['steps_per_s']:.0f} | {p['rtf']:.2f} | "
                     f"{p.get('newton_iterations_mean', float('nan')):.2f} | – | {p['tip_error']:.1e} | – |")
    if h2h:
        lines += ["", f"## Head to head, interleaved ({args.rounds} rounds)", "",
                  "The machine is shared and its speed drifts by tens of per cent over seconds, so the comparison "
                  "that matters is run interleaved: each round runs every case once, in turn; the table gives "
                  "the median over the rounds of steps/s and of the ratio to Exudyn 16 el. within a round.", "",
                  "| case | tip error | steps/s (median) | ratio to Exudyn 16 el. (median of rounds) |",
                  "|---|---|---|---|"]
        for c in h2h:
            lines.append(f"| {c['case']} | {c['error']:.1e} ({c['error_kind']}) | {c['steps_per_s']:.0f} | "
                         f"{c['ratio']:.2f} |")
    lines += ["", "The converged FE reference (32 elements, static) differs from the linear-law elastica by the "
              "Saint-Venant–Kirchhoff bending softening, ≈ 1.8e-5·L for this rod (see tests/verification/test_statics.py); "
              "the numerical error of a run is its distance to the converged FE reference. Exudyn's ANCF cable "
              "has no such softening, so its error is measured against the inextensible elastica."]
    (out / "b1.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'b1.md'} and {out / 'b1.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
