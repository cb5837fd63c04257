"""The twin node on real DDS at 1 kHz: command→state latency, deadline misses, real-time factor.

Each case is ``flexmb demo`` (the node and the player as two processes, discovery on loopback, a
random ROS_DOMAIN_ID) in realtime mode: the player streams the Stewart appendix commands at
1 kHz stamped with the twin's time, the node steps at Δt = 1 ms on the wall clock and answers
every new command at once (``publish_on_command``). Latency is measured by the player, end to end
over DDS: from publishing a command to receiving the status that echoes its stamp.

Writes ``docs/benchmarks/node.json`` and ``docs/benchmarks/node.md``.

    .venv/bin/python benchmarks/node_latency.py [--seconds 60] [--cases bars,frame1,frame4]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "benchmarks"

CASES = {
    "bars": ("scenes/stewart_platform_bars.yaml", "bar-actuator legs, truss platform (9 free DOFs)"),
    "frame1": ("scenes/stewart_platform_1el.yaml", "frame legs, 1 cubic element each"),
    "frame4": ("scenes/stewart_platform.yaml", "frame legs, 4 cubic elements each (the paper's fidelity)"),
}


def run_case(name: str, seconds: float) -> dict:
    scene, what = CASES[name]
    out = ROOT / "build" / "bench_node" / name
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", OPENBLAS_NUM_THREADS="1",
               ROS_DOMAIN_ID=str(random.SystemRandom().randint(1, 200)))
    env.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))
    cmd = [sys.executable, "-m", "ros2_node.cli", "demo", scene, "--mode", "realtime", "--until", str(seconds),
           "--publish-rate", "1000", "--out", str(out)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{name}: demo failed ({p.returncode}):\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}")
    s = json.loads((out / "summary.json").read_text())
    n, pl = s["node"], s["player"]
    return {"case": name, "scene": scene, "what": what, "seconds": seconds, "wall_s": time.perf_counter() - t0,
            "steps": n["steps"], "rtf": n["rtf"], "solver_rtf": n["solver_rtf"],
            "deadline_misses": n["deadline_misses"], "overruns": n["overruns"],
            "step_wall_p50_ms": 1e3 * n["step_wall_time_s"]["p50"], "step_wall_p99_ms": 1e3 * n["step_wall_time_s"]["p99"],
            "latency_p50_ms": 1e3 * pl["latency_s"]["p50"], "latency_p99_ms": 1e3 * pl["latency_s"]["p99"],
            "latency_max_ms": 1e3 * pl["latency_s"]["max"], "latency_count": pl["latency_s"]["count"],
            "node_internal_latency_p50_ms": 1e3 * n["command_to_state_latency_s"]["p50"],
            "node_internal_latency_p99_ms": 1e3 * n["command_to_state_latency_s"]["p99"],
            "tracking_max_m": pl.get("tracking", {}).get("max_position_error_m"),
            "failed_steps": n["failed_steps"], "rejected": sum(n["commands_rejected"].values())}


def write(results: list[dict], seconds: float) -> None:
    DOCS.mkdir(parents=True, exist_ok=True)
    meta = {"python": sys.version.split()[0], "machine": platform.machine(), "cpus": os.cpu_count(),
            "date": time.strftime("%Y-%m-%d"), "seconds": seconds}
    (DOCS / "node.json").write_text(json.dumps({"meta": meta, "results": results}, indent=2) + "\n")
    lines = [
        "# The twin node at 1 kHz on DDS (`benchmarks/node_latency.py`)",
        "",
        f"{seconds:g} s of the Stewart appendix trajectory per case, node and player as two processes on "
        f"loopback DDS ({meta['cpus']} cores, Python {meta['python']}, {meta['date']}). Realtime mode, "
        "Δt = 1 ms, commands at 1 kHz, states published at 1 kHz and on every new command. Latency: "
        "player publish → player receives the status echoing that command's stamp (two DDS hops + "
        "one solver step). Goal (issue 5): p99 ≤ 1 ms and no missed deadline.",
        "",
        "| case | model | RTF | solver alone RTF | missed deadlines | step p50 / p99 (ms) | latency p50 / p99 / max (ms) | pose error max (m) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        miss = f"{r['deadline_misses']} / {r['steps']} ({100 * r['deadline_misses'] / max(r['steps'], 1):.2f} %)"
        track = "—" if r["tracking_max_m"] is None else f"{r['tracking_max_m']:.2e}"
        lines.append(f"| {r['case']} | {r['what']} | {r['rtf']:.3f} | {r['solver_rtf']:.2f} | {miss} | "
                     f"{r['step_wall_p50_ms']:.3f} / {r['step_wall_p99_ms']:.3f} | "
                     f"{r['latency_p50_ms']:.3f} / {r['latency_p99_ms']:.3f} / {r['latency_max_ms']:.2f} | {track} |")
    lines += ["", "A case whose solver alone is slower than real time (solver RTF < 1) cannot meet the "
              "deadlines: it runs behind the wall clock (RTF < 1) and the player's commands then reach it "
              "late; that is the speed programme of issue 7, not a property of the node.", ""]
    (DOCS / "node.md").write_text("\n".join(lines))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--cases", default="bars,frame1,frame4")
    args = ap.parse_args()
    results = []
    for name in args.cases.split(","):
        r = run_case(name, args.seconds)
        print(json.dumps(r), flush=True)
        results.append(r)
    write(results, args.seconds)
    print(f"wrote {DOCS / 'node.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
