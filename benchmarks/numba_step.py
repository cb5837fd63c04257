"""The numba step on every shipped scene (issue 13): steps/s of each dynamic scene and the wall time
of each static one run by load stepping, median of ``--rounds`` runs; written to
docs/benchmarks/numba_step_scenes.{md,json}. (Until 2026-11-29 this also timed the Python Newton
loop it replaced; that loop is gone, and docs/benchmarks/numba_step.md keeps those measurements.)

    .venv/bin/python benchmarks/numba_step.py [--rounds 5] [--steps 400] [--out docs/benchmarks]

``--against TREE`` (a checkout of an older revision, e.g. ``git worktree add /tmp/old 35a2f54``)
instead times the scenes given by ``--scenes`` in that tree and in this one, each in its own
process and numba cache, interleaved round by round, and prints µs per step:

    .venv/bin/python benchmarks/numba_step.py --against /tmp/old --scenes stewart_platform_shell radiator_panels
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

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402

DYNAMIC = ["cantilever_b1", "actuator_arm", "deployable_boom", "rps_manipulator", "stewart_platform_bars",
           "stewart_platform_1el", "stewart_platform", "boom_step", "spin_up", "stewart_platform_shell",
           "right_angle_cantilever", "tendon_arm", "radiator_panels"]
STATIC = ["shell_roll_up", "shell_strip_shear", "shell_pulled_cylinder", "shell_pinched_hemisphere",
          "shell_pinched_cylinder"]          # shell_slit_annulus: ≈ 1 min a run


def _dynamic_rate(model, steps: int) -> float:
    sim = Simulator(model)
    sim.warmup()
    sim.initialize()
    for _ in range(10):
        sim.step()
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    return steps / (time.perf_counter() - t0)


def _static_wall(model) -> float:
    sim = Simulator(model)
    sim.warmup()
    t0 = time.perf_counter()
    sim.initialize()
    while sim.state.t < sim.spec.until - 1e-12:
        sim.step()
    return time.perf_counter() - t0


# µs per step of the default path of whatever tree is first on sys.path (run by --against)
_PROBE = """
import sys, time, statistics
sys.path.insert(0, sys.argv[1])
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_core.simulator import Simulator
sim = Simulator(compile_scene(load_scene(sys.argv[2])))
sim.warmup()
sim.initialize()
for _ in range(20):
    sim.step()
n, blocks = int(sys.argv[3]), []
for _ in range(5):
    t0 = time.perf_counter()
    for _ in range(n):
        sim.step()
    blocks.append((time.perf_counter() - t0) / n * 1e6)
print(statistics.median(blocks))
"""


def times_against(tree: Path, name: str, rounds: int, steps: int) -> dict[str, list[float]]:
    """µs per step of scene ``name`` in ``tree`` ('before') and in this tree ('after'), each in
    its own process and numba cache, interleaved round by round."""
    import subprocess

    times: dict[str, list[float]] = {"before": [], "after": []}
    for _ in range(rounds):
        for label, src in (("before", tree), ("after", ROOT)):
            env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(src) / ".cache" / "numba_against"))
            out = subprocess.run([sys.executable, "-c", _PROBE, str(src), str(ROOT / "scenes" / f"{name}.yaml"),
                                  str(steps)], capture_output=True, text=True, env=env, cwd=src, check=True)
            times[label].append(float(out.stdout.strip().splitlines()[-1]))
    return times


def _against(tree: Path, scenes: list[str], rounds: int, steps: int) -> int:
    for name in scenes:
        times = times_against(tree, name, rounds, steps)
        ratios = [b / a for b, a in zip(times["before"], times["after"])]
        print(f"{name:26s} before {' / '.join(f'{x:.0f}' for x in times['before'])} µs/step, after "
              f"{' / '.join(f'{x:.0f}' for x in times['after'])} µs/step: {statistics.median(ratios):.2f}× "
              "(median of the rounds' ratios)", flush=True)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=400, help="timed steps per dynamic run")
    ap.add_argument("--static-rounds", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks"))
    ap.add_argument("--against", metavar="TREE", help="time --scenes in this older checkout and here instead")
    ap.add_argument("--scenes", nargs="+", default=["stewart_platform_shell", "radiator_panels"])
    args = ap.parse_args()
    if args.against:
        return _against(Path(args.against), args.scenes, args.rounds, args.steps)
    rows = []
    for name in DYNAMIC:
        model = compile_scene(load_scene(ROOT / "scenes" / f"{name}.yaml"))
        rate = statistics.median(_dynamic_rate(model, args.steps) for _ in range(args.rounds))
        rows.append({"scene": name, "kind": "dynamic", "steps_per_s": rate, "dofs": model.ndof,
                     "multipliers": model.n_multipliers})
        print(f"{name:26s} {rate:8.0f} steps/s", flush=True)
    for name in STATIC:
        model = compile_scene(load_scene(ROOT / "scenes" / f"{name}.yaml"))
        wall = statistics.median(_static_wall(model) for _ in range(args.static_rounds))
        rows.append({"scene": name, "kind": "static", "wall_s": wall, "dofs": model.ndof,
                     "multipliers": model.n_multipliers})
        print(f"{name:26s} {wall:7.2f} s", flush=True)
    out = Path(args.out)
    meta = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "platform": platform.platform(), "cpus": os.cpu_count(),
            "rounds": args.rounds, "steps": args.steps, "static_rounds": args.static_rounds}
    (out / "numba_step_scenes.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")
    (out / "numba_step_scenes.md").write_text(_render(meta, rows))
    print(f"wrote {out / 'numba_step_scenes.md'}")
    return 0


def _render(meta: dict, rows: list[dict]) -> str:
    lines = ["# The numba step on the shipped scenes (issue 13)", "",
             f"Generated by `benchmarks/numba_step.py` on {meta['date']} ({meta['platform']}, {meta['cpus']} cores, "
             f"one used): medians of {meta['rounds']} runs of {meta['steps']} steps per dynamic scene and of "
             f"{meta['static_rounds']} whole runs per static scene. Every step is one numba call "
             "(`integrators/fast.py`, `integrators/static_step.py`).", "",
             "## Dynamics", "", "| scene | DOFs | multipliers | steps/s |", "|---|---|---|---|"]
    lines += [f"| {r['scene']} | {r['dofs']} | {r['multipliers']} | {r['steps_per_s']:.0f} |"
              for r in rows if r["kind"] == "dynamic"]
    lines += ["", "## Statics by load stepping: wall time of the run", "", "| scene | DOFs | wall time |",
              "|---|---|---|"]
    lines += [f"| {r['scene']} | {r['dofs']} | {r['wall_s']:.2f} s |" for r in rows if r["kind"] == "static"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
