"""The held tangent of modified Newton, fixed or following the shells' rotation (``solver.held_tangent``),
on the dynamic shell scenes: Newton iterations and factorizations per step, µs per step, and how far
each run's states are from the root (a full-Newton run at ``--root-tolerance``), all in one process,
the two variants interleaved block by block; then each scene's whole run with each variant (its
iterations, factorizations, sub-steps, refusals, failures, wall time). Writes
docs/benchmarks/held_tangent.{md,json}.

    .venv/bin/python benchmarks/held_tangent.py [--steps 2000] [--blocks 5] [--out docs/benchmarks]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402

SCENES = {"stewart_platform_shell": 2000, "radiator_panels": 600}     # steps (Δt 1 ms and 5 ms)
VARIANTS = ("fixed", "corotated")


def _sim(name: str, **solver) -> Simulator:
    sim = Simulator(compile_scene(load_scene(ROOT / "scenes" / f"{name}.yaml", solver or None)))
    sim.warmup()
    sim.initialize()
    return sim


def _states(sim: Simulator, steps: int, every: int) -> tuple[np.ndarray, int]:
    """Every ``every``-th state ``(steps // every, ndof)`` of ``steps`` steps, and their iterations."""
    rows, iterations = [], 0
    for k in range(steps):
        iterations += sim.step().iterations
        if k % every == every - 1:
            rows.append(sim.state.q.copy())
    return np.array(rows), iterations


def measure(name: str, steps: int, blocks: int, root_tolerance: float, every: int = 10) -> dict:
    """One scene: the root, then the variants stepped in ``blocks`` interleaved blocks."""
    root, _ = _states(_sim(name, newton="full", tolerance=root_tolerance), steps, every)
    sims = {v: _sim(name, held_tangent=v) for v in VARIANTS}
    seen = {v: [] for v in VARIANTS}
    its = {v: 0 for v in VARIANTS}
    wall = {v: [] for v in VARIANTS}
    size = steps // blocks
    for _ in range(blocks):
        for v in VARIANTS:
            t0 = time.perf_counter()
            q, n_it = _states(sims[v], size, every)
            wall[v].append((time.perf_counter() - t0) / size * 1e6)
            seen[v].append(q)
            its[v] += n_it
    out = {"scene": name, "steps": size * blocks, "tolerance": sims["fixed"].spec.tolerance,
           "root_tolerance": root_tolerance}
    for v in VARIANTS:
        dist = np.abs(np.concatenate(seen[v]) - root[:len(np.concatenate(seen[v]))]).max(axis=1)
        out[v] = {"iterations_per_step": its[v] / (size * blocks),
                  "factorizations": int(sims[v]._dynamic.tangent_updates),
                  "us_per_step": statistics.median(wall[v]), "us_per_step_blocks": wall[v],
                  "root_distance_max_m": float(dist.max()), "root_distance_median_m": float(np.median(dist))}
    return out


def whole_run(name: str, variant: str) -> dict:
    """The scene's whole run (``Simulator.run`` to its ``until``) with one variant: its statistics."""
    sim = _sim(name, held_tangent=variant)
    t0 = time.perf_counter()
    sim.run(sim.spec.until)
    wall = time.perf_counter() - t0
    s = sim.stats
    return {"steps": s.steps, "iterations_per_step": s.iterations_total / s.steps, "iterations_max": s.iterations_max,
            "substepped": s.substepped_steps, "refused": s.guard_rejected_steps, "unconverged": s.unconverged_steps,
            "factorizations": int(sim._dynamic.tangent_updates), "wall_s": wall}


def _render(meta: dict, rows: list[dict]) -> str:
    lines = ["# The held tangent: fixed or following the shells' rotation (`benchmarks/held_tangent.py`)", "",
             f"{meta['date']}, {meta['platform']}, {meta['cpus']} cores. Each scene at its own tolerance, "
             "modified Newton; the two variants in one process, stepped in interleaved blocks "
             f"({meta['blocks']} each, µs per step: median of the blocks); distance from the root: the "
             f"largest |q − q_root| (m or –) over every 10th state, q_root from full Newton at "
             f"{meta['root_tolerance']:g}.", "",
             "| scene | steps | held tangent | Newton iterations / step | factorizations | µs / step | "
             "distance from the root, max / median |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        for v in VARIANTS:
            x = r[v]
            lines.append(f"| {r['scene']} | {r['steps']} | {v} | {x['iterations_per_step']:.3f} | "
                         f"{x['factorizations']} | {x['us_per_step']:.0f} | {x['root_distance_max_m']:.1e} / "
                         f"{x['root_distance_median_m']:.1e} |")
        lines.append(f"| | | fixed / corotated | | | {r['fixed']['us_per_step'] / r['corotated']['us_per_step']:.2f}× | |")
    lines += ["", "Whole runs (`Simulator.run` to the scene's `until`, steps batched as `flexmb run` batches them):", "",
              "| scene | held tangent | steps | Newton iterations / step (most) | factorizations | sub-stepped | "
              "refused | unconverged | wall (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for v in VARIANTS:
            w = r["whole"][v]
            lines.append(f"| {r['scene']} | {v} | {w['steps']} | {w['iterations_per_step']:.3f} ({w['iterations_max']}) | "
                         f"{w['factorizations']} | {w['substepped']} | {w['refused']} | {w['unconverged']} | "
                         f"{w['wall_s']:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=None, help="steps per scene (default: 2000 and 600)")
    ap.add_argument("--blocks", type=int, default=5)
    ap.add_argument("--root-tolerance", type=float, default=1e-12)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks"))
    args = ap.parse_args()
    rows = []
    for name in args.scenes:
        rows.append(measure(name, args.steps or SCENES[name], args.blocks, args.root_tolerance))
        r = rows[-1]
        r["whole"] = {v: whole_run(name, v) for v in VARIANTS}
        print(name, {v: {k: r[v][k] for k in ("iterations_per_step", "factorizations", "us_per_step",
                                                  "root_distance_max_m")} for v in VARIANTS}, flush=True)
    meta = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "platform": platform.platform(), "cpus": os.cpu_count(),
            "blocks": args.blocks, "root_tolerance": args.root_tolerance}
    out = Path(args.out)
    (out / "held_tangent.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")
    (out / "held_tangent.md").write_text(_render(meta, rows))
    print(f"wrote {out / 'held_tangent.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
