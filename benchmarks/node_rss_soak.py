"""Memory of the twin node over a long real-time run (issue 15: "a 1-hour soak at 1 kHz with RSS flat
after warm-up, growth < 2 MB over the last 50 min").

Runs ``flexmb demo SCENE --mode realtime --until SECONDS`` (the node and the 1 kHz player as two
processes on DDS), finds the node's process and samples its resident set size (``VmRSS`` of
``/proc/PID/status``) every ``--every`` seconds; writes the series and the growth after warm-up to
``docs/benchmarks/node_rss_soak.{md,json}``.

    .venv/bin/python benchmarks/node_rss_soak.py [--seconds 3600] [--every 10] [--warmup 600]
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
GROWTH_MAX_MB = 2.0          # the bound over the run after warm-up


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(d.name))
    return out


def _cmdline(pid: int) -> str:
    try:
        return (Path("/proc") / str(pid) / "cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _rss_mb(pid: int) -> float | None:
    try:
        for line in (Path("/proc") / str(pid) / "status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def _tail(path: Path, chars: int = 2000) -> str:
    text = path.read_text(errors="replace") if path.exists() else ""
    return text[-chars:]


def soak(scene: str, seconds: float, every: float, out: Path) -> tuple[list[tuple], dict]:
    """The demo run; returns [(s since start, node RSS MB, player RSS MB or None)] and its summary."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", ROS_DOMAIN_ID=str(random.SystemRandom().randint(1, 200)))
    env.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))
    # the node's log goes to a file: a pipe read only at the end fills after some minutes of
    # warnings, and the node's publisher thread then blocks in the log write while the stepping
    # thread queues events for it — the RSS growth of 7–9 MB/min measured in earlier soaks (a
    # 2-hour run reached 1.5 GB with the publisher thread in pipe_write, 2026-11-24)
    out.mkdir(parents=True, exist_ok=True)
    log = open(out / "demo.log", "w")
    demo = subprocess.Popen([sys.executable, "-m", "flexmb.cli", "demo", scene, "--mode", "realtime", "--until",
                             str(seconds), "--out", str(out)], env=env, cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=log, text=True)
    t0 = time.monotonic()
    node = None
    while node is None and demo.poll() is None and time.monotonic() - t0 < 120:
        node = next((p for p in _children(demo.pid) if " node " in _cmdline(p)), None)
        time.sleep(0.2)
    if node is None:
        demo.kill()
        raise RuntimeError(f"the node process of the demo was not found: {_tail(out / 'demo.log')}")
    series, player = [], None
    while demo.poll() is None:
        player = player or next((p for p in _children(demo.pid) if " play " in _cmdline(p)), None)
        rss = _rss_mb(node)
        if rss is not None:
            series.append((time.monotonic() - t0, rss, _rss_mb(player) if player else None))
        time.sleep(every)
    demo.wait()
    log.close()
    if demo.returncode != 0:
        raise RuntimeError(f"the demo failed ({demo.returncode}): {_tail(out / 'demo.log')}")
    summary = json.loads((out / "summary.json").read_text())
    return series, summary


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="scenes/stewart_platform_bars.yaml")
    ap.add_argument("--seconds", type=float, default=3600.0, help="s of simulated (= wall) time")
    ap.add_argument("--every", type=float, default=10.0, help="s between RSS samples")
    ap.add_argument("--warmup", type=float, default=600.0, help="s excluded before measuring growth")
    ap.add_argument("--name", default="node_rss_soak")
    a = ap.parse_args()
    load0 = os.getloadavg()[0]
    series, summary = soak(a.scene, a.seconds, a.every, ROOT / "build" / "bench_rss")
    after = [r for t, r, _ in series if t >= a.warmup]
    player_after = [p for t, _, p in series if t >= a.warmup and p is not None]
    player_growth = (player_after[-1] - player_after[0]) if len(player_after) >= 2 else None
    growth = (after[-1] - after[0]) if len(after) >= 2 else float("nan")
    node = summary["node"]
    result = {"scene": a.scene, "seconds": a.seconds, "every_s": a.every, "warmup_s": a.warmup,
              "python": sys.version.split()[0], "date": time.strftime("%Y-%m-%d"), "load_before": load0,
              "rss_start_mb": series[0][1], "rss_at_warmup_mb": after[0] if after else None,
              "rss_end_mb": series[-1][1], "rss_max_mb": max(r for _, r, _ in series),
              "growth_after_warmup_mb": growth, "player_growth_after_warmup_mb": player_growth, "target_met": growth < GROWTH_MAX_MB,
              "steps": node["steps"], "deadline_misses": node["deadline_misses"], "series": series}
    DOCS.mkdir(parents=True, exist_ok=True)
    (DOCS / f"{a.name}.json").write_text(json.dumps(result, indent=1) + "\n")
    marks, next_mark = [], 0.0                       # one row per 5 minutes, and the last sample
    for t, r, pr in series:
        if t >= next_mark:
            marks.append((t, r, pr))
            next_mark += 300.0
    if marks[-1] != series[-1]:
        marks.append(series[-1])
    lines = [f"# Node memory over a {a.seconds / 60:g}-minute real-time run (`benchmarks/node_rss_soak.py`)", "",
             f"`flexmb demo {a.scene} --mode realtime --until {a.seconds:g}`: the twin node and the 1 kHz player "
             f"on DDS, {platform.node()}, {os.cpu_count()} cores, Python {result['python']}, {result['date']}, "
             f"load {load0:.2f} before; the node's VmRSS every {a.every:g} s.", "",
             f"- RSS: {result['rss_start_mb']:.1f} MB at the first sample, {result['rss_at_warmup_mb']:.1f} MB at "
             f"{a.warmup / 60:g} min, {result['rss_end_mb']:.1f} MB at the end (max {result['rss_max_mb']:.1f} MB)",
             f"- growth after warm-up: **{growth:+.2f} MB** over {(a.seconds - a.warmup) / 60:g} min "
             f"(target < {GROWTH_MAX_MB:g} MB: {'met' if result['target_met'] else 'NOT met'})",
             "- the player's (the 1 kHz client's) growth after warm-up: "
             + (f"{player_growth:+.2f} MB" if player_growth is not None else "not sampled"),
             f"- steps {node['steps']}, missed deadlines {node['deadline_misses']}", "",
             "| t (min) | node RSS (MB) | player RSS (MB) |", "|---|---|---|"]
    lines += [f"| {t / 60:.1f} | {r:.1f} | {'' if pr is None else f'{pr:.1f}'} |" for t, r, pr in marks]
    (DOCS / f"{a.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:8]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
