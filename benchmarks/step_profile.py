"""Where the µs of a dynamic step go, for any scene (issue 13: "a profile before and after, naming
what limits each case now"); written to docs/benchmarks/step_profile.{md,json}.

For each scene the run goes step by step, as the twin node and ``flexmb run`` step it, over
``--seconds`` of the scene's own commands and loads (after 20 steps of start-up):

* the whole step (best of 3 runs) and the part inside the numba step
  (``flexmb_core/integrators/fast.py: model_step``, dispatch included), the rest being the Python
  around it;
* Newton iterations and tangent refreshes per step;
* each part of the kernel timed alone in a numba loop at the run's last state — assembly of every
  element group without and with the tangent (``packs.assemble_packed``), the skyline LU factor
  and solve (``packs.factor_packed``, ``packs.solve_packed``) — times its calls per step, and
  what is left of the kernel (predictor, inertial residual, rates, energies, step guard).

``--before TREE`` (a checkout of an older revision, e.g. ``git worktree add /tmp/old cb17d11``,
the tree before issue 13) also times each scene in that tree and in this one, in separate
processes, interleaved round by round (``numba_step.py --against``'s probe), and reports the
speed-up.

    .venv/bin/python benchmarks/step_profile.py [--scenes stewart_platform_1el stewart_platform_shell]
        [--seconds 0.5] [--before /tmp/old --rounds 5]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

import flexmb_core.integrators.fast as fast  # noqa: E402
from flexmb_core.integrators.packs import (L_KDATA, L_MASSK, L_PAR, L_RF, L_DQ, L_VEVAL, L_ZLAM, P_DAMPED,  # noqa: E402
                                           P_NMULT, assemble_packed, factor_packed, solve_packed)
from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402

SCENES = ["stewart_platform_bars", "stewart_platform_1el", "stewart_platform_1el_truss", "stewart_platform",
          "stewart_platform_shell", "radiator_panels"]


@njit
def _rep_assemble(k, q, v, lam, lam_rate, c_v, refresh, no_dlam, mult, r, kdata, cf, ci, wf, wi, lay, par):
    s = 0.0
    for _ in range(k):
        s += assemble_packed(q, v, lam, lam_rate, c_v, refresh, no_dlam, mult, r, kdata, cf, ci, wf, wi, lay, par)[0]
    return s


@njit
def _rep_factor(k, kd, kdata, mass, coef, env, inv_diag, stats, nmult, wf, wi, lay, par):
    ok = True
    for _ in range(k):
        if nmult:           # with multipliers the factor augments the tangent in place: start again
            kdata[:] = kd
        ok = ok and factor_packed(kdata, mass, coef, env, inv_diag, stats, nmult, wf, wi, lay, par)
    return ok


@njit
def _rep_solve(k, rf, dq, env, inv_diag, stats, wf, wi, lay, par):
    s = 0.0
    for _ in range(k):
        s += solve_packed(rf, dq, env, inv_diag, stats, wf, wi, lay, par)
    return s


def best_us(f, *args, k: int = 500) -> float:
    """µs per repetition of the njit loop ``f(k, *args)``: best of 7, after a first call."""
    f(1, *args)
    times = []
    for _ in range(7):
        t0 = time.perf_counter()
        f(k, *args)
        times.append((time.perf_counter() - t0) / k * 1e6)
    return min(times)


def _sim(model) -> Simulator:
    sim = Simulator(model)
    sim.warmup()
    sim.initialize()
    for _ in range(20):
        sim.step()
    return sim


def _run(model, steps: int, wrapped: bool) -> tuple[float, float, tuple[float, float], Simulator]:
    """µs per step of ``steps`` steps, inside the numba step (when ``wrapped``), Newton iterations
    and tangent refreshes per step, and the simulator at the end."""
    kern = fast.model_step
    spent = [0]

    def timed(*a):
        t0 = time.perf_counter_ns()
        code = kern(*a)
        spent[0] += time.perf_counter_ns() - t0
        return code
    sim = _sim(model)
    it0, tan0 = sim.stats.iterations_total, sim._dynamic.tangent_updates
    fast.model_step = timed if wrapped else kern
    try:
        t0 = time.perf_counter()
        for _ in range(steps):
            sim.step()
        wall = time.perf_counter() - t0
    finally:
        fast.model_step = kern
    counts = ((sim.stats.iterations_total - it0) / steps, (sim._dynamic.tangent_updates - tan0) / steps)
    return wall / steps * 1e6, spent[0] / steps / 1000, counts, sim


def _components(sim: Simulator) -> dict[str, float]:
    """µs per call of the kernel's parts, at ``sim``'s state (its factors are overwritten)."""
    f = sim._dynamic.fast
    d, dlay, f_ext, r, env, inv_diag, stats = f._shared
    cf, ci, wf, wi = f._packs
    lay, item = f._lay, f.packs.view
    par = item(L_PAR, 0)
    st = sim.state
    damped = par[P_DAMPED] != 0.0
    v = item(L_VEVAL)
    v[:] = st.v
    c_v = sim._dynamic.gamma / (sim._dynamic.beta * sim.spec.dt) if damped else 0.0
    lam_rate = st.lam_rate if damped else item(L_ZLAM)
    kdata = item(L_KDATA)
    no_dlam = sim.spec.dt < 0.0
    args = (st.q, v, st.lam, lam_rate, c_v)
    tail = (no_dlam, st.mult, r, kdata, cf, ci, wf, wi, lay, par)
    out = {"assembly, residual": best_us(_rep_assemble, *args, False, *tail, k=200),
           "assembly, residual + tangent": best_us(_rep_assemble, *args, True, *tail, k=50)}
    coef = float(sim.data.tan[1]) or 1.0
    out["LU factor"] = best_us(_rep_factor, kdata.copy(), kdata, item(L_MASSK), coef, env, inv_diag, stats,
                                int(par[P_NMULT]), wf, wi, lay, par, k=50)
    rf = item(L_RF)
    rf[:] = np.linspace(-1.0, 1.0, rf.size)
    out["LU solve"] = best_us(_rep_solve, rf, item(L_DQ), env, inv_diag, stats, wf, wi, lay, par, k=500)
    return out


def profile(name: str, seconds: float) -> dict:
    model = compile_scene(load_scene(ROOT / "scenes" / f"{name}.yaml"))
    steps = max(50, int(round(seconds / model.scene.solver.dt)))
    totals, inside = [], []
    for wrapped in (False, True) * 3:
        total, kern, (its, tans), sim = _run(model, steps, wrapped)
        (inside if wrapped else totals).append(kern if wrapped else total)
    comp = _components(sim)
    total, kernel = min(totals), min(inside)
    parts = {"assembly, residual": (its - tans, comp["assembly, residual"]),
             "assembly, residual + tangent": (tans, comp["assembly, residual + tangent"]),
             "LU factor": (tans, comp["LU factor"]), "LU solve": (its, comp["LU solve"])}
    rest = kernel - sum(c * us for c, us in parts.values())
    return {"scene": name, "free_dofs": int(model.nfree), "multipliers": int(model.n_multipliers),
            "dt": model.scene.solver.dt, "steps": steps, "total_us": total, "kernel_us": kernel,
            "python_us": total - kernel, "iterations": its, "refreshes": tans,
            "parts": {k: {"calls": c, "us_per_call": us, "us_per_step": c * us} for k, (c, us) in parts.items()},
            "rest_of_kernel_us": rest}


def before_after(tree: Path, name: str, rounds: int, steps: int) -> dict:
    """µs per step in ``tree`` and here (``numba_step.py --against``'s measurement), medians."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from numba_step import times_against
    times = times_against(tree, name, rounds, steps)
    ratios = [b / a for b, a in zip(times["before"], times["after"])]
    return {"before_us": statistics.median(times["before"]), "after_us": statistics.median(times["after"]),
            "speedup": statistics.median(ratios), "before_all": times["before"], "after_all": times["after"]}


def _limits(p: dict) -> str:
    """The two largest shares of the step, in words."""
    shares = {k: v["us_per_step"] for k, v in p["parts"].items()}
    shares["rest of the kernel"] = p["rest_of_kernel_us"]
    shares["Python around the call"] = p["python_us"]
    top = sorted(shares.items(), key=lambda kv: -kv[1])[:2]
    return "; ".join(f"{k} {v / p['total_us'] * 100:.0f} %" for k, v in top)


def render(meta: dict, rows: list[dict]) -> str:
    lines = ["# Where a step goes — the Stewart twins, the shell plate and the radiator panels", "",
             f"Generated by `benchmarks/step_profile.py` on {meta['date']} ({meta['machine']}, {meta['cpus']} cores, "
             f"one used; commit {meta['commit']}). The machine is shared and its speed drifts by tens of per cent "
             "over seconds: the totals are the best of 3 runs of the same steps, the parts are each kernel "
             "timed alone in a numba loop at the run's last state (best of 7) × its calls per step, so they add "
             "up only approximately. Steps go one by one, with the scene's own commands and loads, as the twin "
             "node and `flexmb run` step them.", ""]
    if any("before" in r for r in rows):
        lines += [f"**Before / after** (`--before`: the tree at {meta['before']}, each scene in its own process "
                  f"and numba cache, {meta['rounds']} interleaved rounds, medians):", "",
                  "| scene | before (µs/step) | after (µs/step) | speed-up (median of the rounds' ratios) |",
                  "|---|---|---|---|"]
        for r in rows:
            if "before" in r:
                b = r["before"]
                lines.append(f"| {r['scene']} | {b['before_us']:.0f} | {b['after_us']:.0f} | {b['speedup']:.2f}× |")
        lines.append("")
    lines += ["| scene | free DOFs | multipliers | µs/step | in the numba step | Python around it | Newton it./step "
              "| tangent refreshes/step | assembly, residual | assembly + tangent | LU factor | LU solve | rest of the "
              "kernel | what limits it now (share of the step) |", "|" + "---|" * 14]
    for r in rows:
        p = r["parts"]
        lines.append(
            f"| {r['scene']} | {r['free_dofs']} | {r['multipliers']} | {r['total_us']:.1f} | {r['kernel_us']:.1f} | "
            f"{r['python_us']:.1f} | {r['iterations']:.2f} | {r['refreshes']:.3f} | "
            + " | ".join(f"{p[k]['us_per_step']:.1f} ({p[k]['us_per_call']:.1f} × {p[k]['calls']:.2f})"
                         for k in ("assembly, residual", "assembly, residual + tangent", "LU factor", "LU solve"))
            + f" | {r['rest_of_kernel_us']:.1f} | {_limits(r)} |")
    lines += ["", "Parts: µs per step (µs per call × calls per step). 'Rest of the kernel': predictor, inertial "
              "residual M(a + c_m v), rates, energies, step guard and argument dispatch.", ""]
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=SCENES)
    ap.add_argument("--seconds", type=float, default=0.5, help="simulated time per run (s)")
    ap.add_argument("--before", metavar="TREE", help="an older checkout to time each scene against")
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds of --before")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks"))
    ap.add_argument("--name", default="step_profile")
    args = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=ROOT).stdout.strip()
    meta = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": platform.platform(), "cpus": os.cpu_count(),
            "commit": commit, "seconds": args.seconds}
    rows = []
    for name in args.scenes:
        row = profile(name, args.seconds)
        if args.before:
            row["before"] = before_after(Path(args.before), name, args.rounds, 400)
            meta["before"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                            cwd=args.before).stdout.strip()
            meta["rounds"] = args.rounds
        rows.append(row)
        print(f"{name}: {row['total_us']:.1f} µs/step ({row['kernel_us']:.1f} in the kernel), {_limits(row)}"
              + (f", {row['before']['speedup']:.2f}× the tree before" if "before" in row else ""), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{args.name}.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")
    (out / f"{args.name}.md").write_text(render(meta, rows))
    print(f"wrote {out / (args.name + '.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
