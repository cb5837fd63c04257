"""Curved shells at large deflection (issue 16): writes docs/benchmarks/shell_paths.md and its plots.

Three shipped scene files, traced by arc length (``solver.control: arc_length``, monitor at a named
mesh point) to the maximum load of the geometrically nonlinear benchmarks of Sze, Liu & Lo (2004),
"Popular benchmark problems for geometric nonlinear analysis of shells", Finite Elements in
Analysis and Design 40, 1551–1569:

- ``scenes/shell_pulled_cylinder.yaml``: the open-ended cylinder pulled out (their 3.5),
  P_max = 40 000, the octant carrying P/4;
- ``scenes/shell_pinched_cylinder.yaml``: the pinched cylinder on rigid diaphragms (their 3.6),
  the scene's R, L, t, E set to theirs (R = 100, L = 200, t = 1, E = 3e4), P_max = 12 000, the
  octant carrying P/4 (their points A and B are the scene's C and E);
- ``scenes/shell_pinched_hemisphere.yaml``: the hemisphere with an 18° hole (their 3.4),
  P_max = 400, the quarter carrying P/2 at each load point.

Each case runs on the scene's mesh and on a finer one; the table gives the paths at a few load
levels and the difference between the meshes. The published reference values are kept out of the
project (they stay an independent check), as in ``tests/verification/test_shell_scenes.py``.

Usage: ``python benchmarks/shell_paths.py [--out docs/benchmarks] [--quick] [--cases pulled,pinched,hemisphere]``
(``--quick``: the scenes' meshes only, ~3 min; the default adds 16 × 16 cells, ~1 h on one core;
``--render JSON`` rewrites the report and plots from a run's ``shell_paths.json``).
"""

from __future__ import annotations

import argparse
import copy
import datetime
import json
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flexmb_core.integrators.path_following import PathFollower
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import scene_from_dict
from flexmb_core.scene.loader import parse_yaml
from flexmb_core.simulator import Simulator

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Case:
    """One benchmark: a scene, how it is loaded and traced, and the curves it reports."""

    key: str
    scene: str
    title: str
    p_max: float                      # the benchmark's maximum load
    share: float                      # the part of P the modelled piece carries at each load point
    meshes: tuple                     # (scene's mesh, finer mesh): divisions
    arc: dict                         # solver.arc_length
    monitor: dict
    curves: tuple                     # (label, point, component, sign): what is plotted and tabled
    edits: dict = field(default_factory=dict)     # shell mesh/thickness/material/points set to the benchmark's
    note: str = ""                                # what the paths show (under the tables)


CASES = (
    Case("pulled", "shell_pulled_cylinder", "Open-ended cylinder pulled out (Sze et al. 3.5)", 40000.0, 0.25,
         ((8, 8), (16, 16)), {"initial": 0.05, "min": 1e-4, "max": 1.0, "target_iterations": 5},
         {"node": "tube.A", "component": "z"},
         (("w_A", "A", 2, 1.0), ("−u_B", "B", 1, -1.0), ("−u_C", "C", 1, -1.0)),
         note="The free end's section snaps through near P/P_max = 0.5: a load maximum and a load minimum close "
              "together (the limit points above), −u_B jumping on and −u_C turning back; past it the pull-out "
              "stiffens again. Both meshes trace the same path."),
    Case("pinched", "shell_pinched_cylinder", "Pinched cylinder on rigid diaphragms (Sze et al. 3.6)", 12000.0, 0.25,
         ((8, 8), (16, 16)), {"initial": 0.3, "min": 1e-4, "max": 5.0, "target_iterations": 5},
         {"node": "tube.C", "component": "z"},
         (("−w_A", "C", 2, -1.0), ("u_B", "E", 1, 1.0)),
         {"radius": 100.0, "length": 100.0, "thickness": 1.0, "E": 3.0e4,
          "points": {"C": [100.0, 0.0, 100.0], "E": [100.0, 100.0, 0.0]}},
         note="The pinched region wrinkles: each mesh crosses a series of local snaps (the limit points above, "
              "traced through by the arc length) whose loads depend on the mesh, and past them the two paths "
              "approach each other. A mesh-converged path of this case needs finer meshes than these two."),
    Case("hemisphere", "shell_pinched_hemisphere", "Hemisphere with an 18° hole (Sze et al. 3.4)", 400.0, 0.5,
         ((8, 8), (16, 16)), {"initial": 0.05, "min": 1e-4, "max": 2.0, "target_iterations": 5},
         {"node": "hemi.A", "component": "x"},
         (("u_A", "A", 0, 1.0), ("−u_B", "B", 1, -1.0)),
         note="The hemisphere stiffens without a limit point, the inward push (−u_B) twice the outward pull (u_A) "
              "at P_max; the two meshes agree closely."),
)


def scene_data(case: Case, divisions: tuple) -> dict:
    """The case's scene file as data, loaded to P_max at load factor 1 and set to trace by arc length."""
    d = parse_yaml((ROOT / "scenes" / f"{case.scene}.yaml").read_text(), case.scene)
    shell = next(iter(d["shells"].values()))
    shell["mesh"]["divisions"] = list(divisions)
    e = case.edits
    if e:
        shell["mesh"].update(radius=e["radius"], length=e["length"])
        shell["thickness"] = e["thickness"]
        d["materials"][shell["material"]]["E"] = e["E"]
        shell["points"].update(e["points"])
    for f in d["loads"]["forces"].values():
        unit = np.array(f["force"], dtype=float)
        f["force"] = (unit / np.linalg.norm(unit) * case.p_max * case.share).tolist()
    d["solver"] = {"analysis": "static", "control": "arc_length", "arc_length": dict(case.arc),
                   "monitor": dict(case.monitor), "until_load_factor": 1.0, "max_steps": 2000}
    return d


def trace(case: Case, divisions: tuple) -> dict:
    """The path: load factor and the case's curves at every converged point, with its cost."""
    d = scene_data(case, divisions)
    model = compile_scene(scene_from_dict(copy.deepcopy(d), source=case.scene))
    sim = Simulator(model)
    pf = PathFollower(sim)
    shell = next(iter(d["shells"].values()))
    name = next(iter(d["shells"]))
    gids = [model.node_ydofs[model.node(f"{name}.{pt}"), comp] for _, pt, comp, _ in case.curves]
    signs = np.array([s for *_, s in case.curves])
    values = []

    def record(s, _res) -> None:
        values.append(signs * (s.state.q[gids] - model.q0[gids]))

    sim.warmup()
    t0 = time.perf_counter()
    pf.initialize()
    record(sim, None)
    pf.run(record)
    wall = time.perf_counter() - t0
    rep = pf.report()
    return {"divisions": list(divisions), "cells": int(np.prod(divisions)), "ndof": int(model.ndof),
            "nfree": int(model.nfree), "thickness": shell["thickness"],
            "load_factor": rep["path"]["load_factor"], "values": np.array(values).T.tolist(),
            "iterations": int(sum(rep["path"]["iterations"])), "increments": len(rep["path"]["load_factor"]) - 1,
            "limit_points": rep["limit_points"], "bifurcations": rep["bifurcations"], "wall_s": wall}


def at_load(lam: np.ndarray, y: np.ndarray, x: float) -> float:
    """y on the path where the load factor last crosses x (linear between the bracketing points):
    past a snap, the branch that carries the load on."""
    for i in range(len(lam) - 2, -1, -1):
        a, b = lam[i], lam[i + 1]
        if min(a, b) <= x <= max(a, b) and a != b:
            return float(y[i] + (x - a) / (b - a) * (y[i + 1] - y[i]))
    return float("nan")


def plot(path: Path, case: Case, runs: list) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=90)
    colors = ("C0", "C1", "C2")
    for k, (label, *_rest) in enumerate(case.curves):
        for run, style in zip(runs, ("--", "-")):
            n = "×".join(map(str, run["divisions"]))
            ax.plot(run["values"][k], np.array(run["load_factor"]) * case.p_max, style, color=colors[k], lw=1.2,
                    label=f"{label}, {n} cells")
    ax.set(title=case.title, xlabel="displacement", ylabel="load P")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def report(case: Case, runs: list) -> list[str]:
    lines = [f"## {case.title}: `scenes/{case.scene}.yaml`", "", f"![{case.key}](shell_paths_{case.key}.png)", ""]
    if case.edits:
        e = case.edits
        lines += [f"The scene's radius, length, thickness and E are set to the benchmark's (R = {e['radius']:g}, "
                  f"half-length {e['length']:g}, t = {e['thickness']:g}, E = {e['E']:g}), its points moved with them.",
                  ""]
    lines += [f"P_max = {case.p_max:g}; the modelled piece carries {case.share:g} P at each load point. Arc length "
              f"(cylindrical, Δl ≤ {case.arc['max']:g}), monitor {case.monitor['node']} "
              f"{case.monitor['component']}.",
              "", "| cells | DOFs | increments | Newton it. | wall (s) | limit points | bifurcations |",
              "|---|---|---|---|---|---|---|"]
    for r in runs:
        lims = ", ".join(f"{c['kind']} {c['load_factor'] * case.p_max:.5g}" for c in r["limit_points"]) or "none"
        lines.append(f"| {'×'.join(map(str, r['divisions']))} | {r['ndof']} | {r['increments']} | {r['iterations']} "
                     f"| {r['wall_s']:.1f} | {len(r['limit_points'])}: {lims[:160]} | {len(r['bifurcations'])} |")
    labels = [c[0] for c in case.curves]
    mesh = ["×".join(map(str, r["divisions"])) for r in runs]
    head = "| P/P_max | " + " | ".join(f"{lb}, {m}" for m in mesh for lb in labels)
    if len(runs) > 1:
        head += f" | largest difference {mesh[0]} − {mesh[-1]}"
    lines += ["", head + " |", "|" + "---|" * head.count("|")]
    for x in (0.1, 0.25, 0.5, 0.75, 1.0):
        row = [[at_load(np.array(r["load_factor"]), np.array(r["values"][k]), x) for k in range(len(labels))]
               for r in runs]
        cells = [f"{x:g}"] + [f"{v:.3f}" for vals in row for v in vals]
        if len(runs) > 1:
            dev = max(abs(c - f) / max(abs(f), 1e-12) for c, f in zip(row[0], row[-1]))
            cells.append(f"{dev * 100:.1f} %")
        lines.append("| " + " | ".join(cells) + " |")
    if case.note:
        lines += ["", case.note]
    lines.append("")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks"))
    ap.add_argument("--quick", action="store_true", help="the scenes' meshes only")
    ap.add_argument("--cases", default=",".join(c.key for c in CASES), help="the cases to run (comma-separated); "
                    "the report also shows the other cases of an earlier run in the same --out")
    ap.add_argument("--render", metavar="JSON", help="write the report and plots from a shell_paths.json (no runs)")
    args = ap.parse_args()
    done = json.loads(Path(args.render).read_text()) if args.render else {}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    how = (f"Rendered by `benchmarks/shell_paths.py --render` from the runs in `{Path(args.render).name}` on"
           if args.render else f"Generated by `benchmarks/shell_paths.py{' --quick' if args.quick else ''}` on")
    lines = [f"{how} {datetime.datetime.now():%Y-%m-%d %H:%M:%S} ({platform.platform()}, one core; other jobs may "
             "share the machine).", "", "# Curved shells at large deflection: load–displacement paths", "",
             "The three curved-shell scene files of issue 16, traced by arc length to the maximum load of "
             "the geometrically nonlinear benchmarks of Sze, Liu & Lo (2004), *Popular benchmark problems for "
             "geometric nonlinear analysis of shells*, Finite Elem. Anal. Des. 40:1551–1569, each on the "
             "scene's mesh and a finer one (the published values are kept out of the project: they stay an "
             "independent check). Cubic triangles with the assumed strains (`shell_locking.md`), two per "
             "cell. The tables read each path where the load last crosses the level (after a snap, the "
             "branch that carries the load on). Reproduce: `python benchmarks/shell_paths.py`.",
             ""]
    # the cases run now join those of an earlier run (their paths kept in the JSON): one case can be
    # re-run alone, and a long run keeps what it has done so far
    store = out / "shell_paths.json"
    results = done or (json.loads(store.read_text()) if store.exists() else {})
    for case in CASES:
        if case.key in args.cases.split(",") and not args.render:
            results[case.key] = [trace(case, m) for m in (case.meshes[:1] if args.quick else case.meshes)]
            store.write_text(json.dumps(results, indent=1))
            print(f"{case.key}: done", flush=True)
        if case.key in results:
            plot(out / f"shell_paths_{case.key}.png", case, results[case.key])
            lines += report(case, results[case.key])
    (out / "shell_paths.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
