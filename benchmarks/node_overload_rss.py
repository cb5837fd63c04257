"""The twin node's memory through an overload (issue 15, README "Memory"): a few minutes instead of
a 1-hour soak.

Each run: ``flexmb node SCENE --mode realtime`` and ``flexmb play SCENE --mode realtime --rate R``
(two processes on DDS, localhost only, a random domain), ``--calm`` s undisturbed, then ``--hogs``
busy-looping processes for ``--overload`` s (the node's executor thread then gets less CPU than
1 kHz commands need, as beside ``make test``), then ``--after`` s undisturbed again; the node's
``VmRSS`` every second. Two ways of taking commands, interleaved run by run on the same machine:

- ``inline``: each command applied inside rclpy's events-executor callback and nothing else (the
  node before the fix; ``ros2_node.node.DRAIN_HISTORIES = False``);
- ``drain``: the same, and after a spin that applied a command the node takes what else waits in
  the command histories itself and, when more than one waited, spins once without waiting, then applies
  those (the node now).

Then ``--latency-runs`` calm runs of each (no hogs), interleaved, for the command→state latency
(node summary) and the player's round trip. First, the mechanism without the twin and without
machine load (``--bare`` s, 0 to skip): a bare rclpy node on the same executor and QoS (keep last
10, best effort, ``std_msgs/Float64MultiArray``) whose callback sleeps 3 ms per message for the
middle third of the run, fed at 1 kHz: the executor then takes ≈ 320 messages a second of 1000.
Writes ``docs/benchmarks/node_overload_rss.{md,json}``.

    .venv/bin/python benchmarks/node_overload_rss.py [--rounds 2] [--calm 20] [--overload 40]
        [--after 40] [--hogs 6] [--latency-runs 2] [--latency-seconds 30]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import signal
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from node_rss_soak import _rss_mb  # noqa: E402  (the VmRSS reader of the long soak)
DOCS = ROOT / "docs" / "benchmarks"
OUT = ROOT / "build" / "bench_overload"
VARIANTS = ("inline", "drain")
# the node under one of the two ways (the flexmb CLI, with the module switch set before it runs)
_NODE = ("import sys; import ros2_node.node as N; N.DRAIN_HISTORIES = {drain}; "
         "from flexmb.cli import main; sys.exit(main(sys.argv[1:]))")
_HOG = "while True: pass"
# s between the player's start and the first sample (discovery, the first commands)
WARMUP = 5.0


def _stop(proc: subprocess.Popen, timeout: float = 60.0) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def run(variant: str, scene: str, rate: float, calm: float, overload: float, after: float, hogs: int,
        tag: str) -> dict:
    """One run; the node's RSS series [(s since it stepped, MB, phase)] and both summaries."""
    out = OUT / tag
    out.mkdir(parents=True, exist_ok=True)
    node_json, player_json = out / "node.json", out / "player.json"
    for f in (node_json, player_json):
        f.unlink(missing_ok=True)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", OPENBLAS_NUM_THREADS="1",
               ROS_DOMAIN_ID=str(random.SystemRandom().randint(1, 100)))
    env.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))
    total = calm + overload + after
    node = subprocess.Popen([sys.executable, "-c", _NODE.format(drain=variant == "drain"), "node", scene,
                             "--mode", "realtime", "--summary-json", str(node_json), "--quiet"],
                            env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    log: list[str] = []
    configured = threading.Event()

    def read_log():
        for line in node.stderr:
            log.append(line)
            if "warm-up" in line:           # configured: it activates and steps right after
                configured.set()

    threading.Thread(target=read_log, daemon=True).start()
    player = None
    hog_procs: list[subprocess.Popen] = []
    series = []
    try:
        if not configured.wait(600.0):
            raise RuntimeError(f"{tag}: the node did not configure: {''.join(log)[-2000:]}")
        player = subprocess.Popen([sys.executable, "-m", "flexmb.cli", "play", scene, "--mode", "realtime",
                                   "--until", str(total + WARMUP + 2.0), "--rate", str(rate), "--json",
                                   str(player_json), "--quiet", "--timeout", "120"],
                                  env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=open(out / "player.err", "w"))
        time.sleep(WARMUP)                  # the player's discovery and first commands
        t0 = time.monotonic()
        while node.poll() is None:
            t = time.monotonic() - t0
            if t >= total:
                break
            phase = "calm" if t < calm else ("overload" if t < calm + overload else "after")
            if phase == "overload" and not hog_procs:
                hog_procs = [subprocess.Popen([sys.executable, "-c", _HOG]) for _ in range(hogs)]
            if phase == "after" and hog_procs:
                for h in hog_procs:
                    h.kill()
                    h.wait()
                hog_procs = []
            rss = _rss_mb(node.pid)
            if rss is not None:
                series.append((round(t, 2), rss, phase))
            time.sleep(1.0 - (time.monotonic() - t0) % 1.0)
        if player is not None:
            try:
                player.wait(timeout=60.0)   # it ends by itself and writes its summary
            except subprocess.TimeoutExpired:
                pass
    finally:
        for h in hog_procs:
            h.kill()
            h.wait()
        if player is not None:
            _stop(player)
        _stop(node)
    err = "".join(log)
    if not node_json.exists():
        raise RuntimeError(f"{tag}: the node wrote no summary (exit {node.returncode}): {err[-2000:]}")
    n = json.loads(node_json.read_text())
    p = json.loads(player_json.read_text()) if player_json.exists() else {}
    return {"variant": variant, "series": series, "node": n, "player": p}


def _at(series, t: float) -> float:
    """RSS of the last sample at or before t (s)."""
    return [r for s, r, _ in series if s <= t + 1e-9][-1]


def growth(res: dict, calm: float, overload: float, after: float) -> dict:
    s = res["series"]
    end = s[-1][0]
    g = {"calm_mb": _at(s, calm) - s[0][1], "overload_mb": _at(s, calm + overload) - _at(s, calm),
         "after_mb": _at(s, end) - _at(s, calm + overload)}
    g["overload_mb_per_min"] = 60.0 * g["overload_mb"] / overload
    g["after_mb_per_min"] = 60.0 * g["after_mb"] / max(end - calm - overload, 1e-9)
    return g


def _lat(res: dict) -> dict:
    n, p = res["node"], res["player"]
    c = n.get("command_to_state_latency_s", {})
    pl = p.get("latency_s", {})
    return {"node_p50_ms": 1e3 * c.get("p50", float("nan")), "node_p99_ms": 1e3 * c.get("p99", float("nan")),
            "player_p50_ms": 1e3 * pl.get("p50", float("nan")), "player_p99_ms": 1e3 * pl.get("p99", float("nan")),
            "accepted": n.get("commands_accepted"), "deadline_misses": n.get("deadline_misses"),
            "steps": n.get("steps"), "cpu_beyond_solver": n.get("cpu_time_s", {}).get("beyond_solver_core_fraction")}


# -- the mechanism, without the twin: a bare rclpy node with a deliberately slow callback ------------
def _bare_node(variant: str, seconds: float, slow_ms: float) -> None:
    """Prints one JSON line a second: RSS (MB), messages applied and spins in that second."""
    import rclpy
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray
    from ros2_node.taking import take_waiting

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("overload_bare", context=ctx)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
                     durability=DurabilityPolicy.VOLATILE)
    t0 = time.monotonic()
    count = {"applied": 0, "spins": 0}
    state = {"took": False, "draining": False}
    inbox: list = []

    def apply(msg):
        count["applied"] += 1
        if seconds / 3 <= time.monotonic() - t0 < 2 * seconds / 3:
            time.sleep(slow_ms / 1e3)          # the overload: the executor takes ~1/slow_ms messages a s

    def on_message(msg):                       # the node's _on_message
        if state["draining"]:
            inbox.append(msg)
        else:
            state["took"] = True
            apply(msg)

    sub = node.create_subscription(Float64MultiArray, "overload_cmd", on_message, qos)
    ex = EventsExecutor(context=ctx)
    ex.add_node(node)
    last, next_t = dict(count), t0 + 1.0
    while time.monotonic() - t0 < seconds:
        ex.spin_once(timeout_sec=0.05)
        count["spins"] += 1
        if state["took"] and variant == "drain":     # the node's _take_commands, on one subscription
            state["took"] = False
            inbox.extend(take_waiting(sub))
            if len(inbox) > 1:                          # a backlog: drop the stale entries first
                state["draining"] = True
                ex.spin_once(timeout_sec=0.0)
                state["draining"] = False
                count["spins"] += 1
            for m in inbox:
                apply(m)
            inbox.clear()
        now = time.monotonic()
        if now >= next_t:
            next_t += 1.0
            print(json.dumps({"t": round(now - t0, 2), "rss": _rss_mb(os.getpid()),
                              "applied": count["applied"] - last["applied"], "spins": count["spins"] - last["spins"]}),
                  flush=True)
            last = dict(count)
    ex.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=ctx)


def _bare_pub(seconds: float, rate: float) -> None:
    import rclpy
    from rclpy.context import Context
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("overload_bare_pub", context=ctx)
    pub = node.create_publisher(Float64MultiArray, "overload_cmd",
                                QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                                           reliability=ReliabilityPolicy.BEST_EFFORT))
    msg = Float64MultiArray(data=[0.1] * 6)
    t0, k = time.monotonic(), 0
    try:
        while time.monotonic() - t0 < seconds:
            k += 1
            pub.publish(msg)
            wait = t0 + k / rate - time.monotonic()
            if wait > 0:
                time.sleep(wait)
    except KeyboardInterrupt:            # the parent stops the publisher with SIGINT
        pass
    rclpy.shutdown(context=ctx)


def bare(variant: str, seconds: float) -> list[dict]:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", OPENBLAS_NUM_THREADS="1",
               ROS_DOMAIN_ID=str(random.SystemRandom().randint(1, 100)))
    me = [sys.executable, str(Path(__file__).resolve())]
    node = subprocess.Popen(me + ["--role", f"bare-node-{variant}", "--bare", str(seconds)], env=env, cwd=ROOT,
                            stdout=subprocess.PIPE, text=True)
    time.sleep(1.0)
    pub = subprocess.Popen(me + ["--role", "bare-pub", "--bare", str(seconds + 5.0)], env=env, cwd=ROOT)
    out, _ = node.communicate(timeout=seconds + 120)
    _stop(pub)
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def _bare_growth(rows: list[dict], seconds: float) -> dict:
    """RSS growth (MB) over each third (calm, slow callback, calm) and messages applied a second."""
    def at(t):
        return [r["rss"] for r in rows if r["t"] <= t + 0.5][-1]
    third = seconds / 3
    slow = [r["applied"] for r in rows if third + 1 < r["t"] <= 2 * third]
    return {"first_mb": at(third) - at(2.0), "slow_mb": at(2 * third) - at(third),
            "after_mb": rows[-1]["rss"] - at(2 * third),
            "applied_per_s_slow": statistics.median(slow) if slow else None}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="scenes/stewart_platform_bars.yaml")
    ap.add_argument("--rate", type=float, default=2000.0, help="the player's commands per second, overload runs")
    ap.add_argument("--rounds", type=int, default=2, help="overload runs of each variant (interleaved)")
    ap.add_argument("--calm", type=float, default=20.0, help="s before the overload")
    ap.add_argument("--overload", type=float, default=40.0, help="s of busy-looping processes beside the node")
    ap.add_argument("--after", type=float, default=40.0, help="s after the overload")
    ap.add_argument("--hogs", type=int, default=6, help="busy-looping processes during the overload")
    ap.add_argument("--latency-runs", type=int, default=2, help="calm runs of each variant (interleaved)")
    ap.add_argument("--latency-seconds", type=float, default=30.0)
    ap.add_argument("--latency-rate", type=float, default=1000.0, help="the player's commands per second, calm runs")
    ap.add_argument("--name", default="node_overload_rss")
    ap.add_argument("--bare", type=float, default=45.0, help="s of each bare-rclpy run (0: none)")
    ap.add_argument("--role", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.role == "bare-pub":
        _bare_pub(a.bare, 1000.0)
        return 0
    if a.role and a.role.startswith("bare-node-"):
        _bare_node(a.role.removeprefix("bare-node-"), a.bare, 3.0)
        return 0
    load0 = os.getloadavg()[0]
    runs, lat_runs, bare_runs = [], [], []
    for k in range(2 if a.bare > 0 else 0):
        for v in (VARIANTS if k % 2 == 0 else VARIANTS[::-1]):
            rows = bare(v, a.bare)
            bare_runs.append({"variant": v, "growth": _bare_growth(rows, a.bare), "series": rows})
            print("bare", v, k, json.dumps(bare_runs[-1]["growth"]), flush=True)
    for k in range(a.rounds):
        for v in (VARIANTS if k % 2 == 0 else VARIANTS[::-1]):
            res = run(v, a.scene, a.rate, a.calm, a.overload, a.after, a.hogs, f"{v}_{k}")
            res["growth"] = growth(res, a.calm, a.overload, a.after)
            res["summary"] = _lat(res)
            # a player that never streamed (it did not find the twin in time) makes no overload
            res["growth"]["valid"] = res["summary"]["valid"] = bool(res["summary"]["accepted"])
            runs.append(res)
            print(v, k, json.dumps(res["growth"]), json.dumps(res["summary"]), flush=True)
    for k in range(a.latency_runs):
        for v in (VARIANTS if k % 2 == 0 else VARIANTS[::-1]):
            res = run(v, a.scene, a.latency_rate, a.latency_seconds, 0.0, 0.0, 0, f"lat_{v}_{k}")
            res["summary"] = _lat(res)
            res["summary"]["valid"] = bool(res["summary"]["accepted"])
            lat_runs.append(res)
            print("latency", v, k, json.dumps(res["summary"]), flush=True)

    def med(rows, key):
        vals = [r[key] for r in rows if r.get(key) is not None and r.get("valid", True)]
        return statistics.median(vals) if vals else float("nan")

    result = {"scene": a.scene, "rate": a.rate, "latency_rate": a.latency_rate, "calm_s": a.calm, "overload_s": a.overload, "after_s": a.after,
              "hogs": a.hogs, "host": platform.node(), "cores": os.cpu_count(), "date": time.strftime("%Y-%m-%d"),
              "load_before": load0,
              "overload_runs": [{"variant": r["variant"], "growth": r["growth"], "summary": r["summary"],
                                 "series": r["series"]} for r in runs],
              "latency_runs": [{"variant": r["variant"], "summary": r["summary"]} for r in lat_runs],
              "bare_runs": bare_runs}
    DOCS.mkdir(parents=True, exist_ok=True)
    (DOCS / f"{a.name}.json").write_text(json.dumps(result, indent=1) + "\n")
    lines = ["# Node memory through an overload (`benchmarks/node_overload_rss.py`)", "",
             f"`flexmb node {a.scene} --mode realtime` and `flexmb play ... --rate {a.rate:g}` on DDS "
             f"(localhost), {platform.node()}, {os.cpu_count()} cores, {result['date']}, load {load0:.2f} before "
             f"(the machine is shared). Each run: {a.calm:g} s calm, {a.overload:g} s with {a.hogs} busy-looping "
             f"processes beside it, {a.after:g} s calm again; the node's VmRSS every second. `inline`: each "
             "command applied inside the events executor's callback, nothing else (before the fix); `drain`: "
             "the same, and after a spin that applied a command the node takes what else waits in the command "
             "histories itself and, when more than one waited (a backlog), spins once without waiting (the "
             "queue's stale entries then find nothing and are dropped); then it applies what it took (now). "
             "Runs interleaved.", ""]
    if bare_runs:
        third = a.bare / 3
        lines += [f"The mechanism alone (bare rclpy node, same executor and QoS, 1 kHz in; its callback sleeps "
                  f"3 ms per message from {third:g} to {2 * third:g} s): RSS growth in MB.", "",
                  "| run | variant | calm | slow callback | after | messages applied/s while slow |",
                  "|---|---|---|---|---|---|"]
        for i, r in enumerate(bare_runs):
            g = r["growth"]
            lines.append(f"| {i + 1} | {r['variant']} | {g['first_mb']:+.2f} | {g['slow_mb']:+.2f} | "
                         f"{g['after_mb']:+.2f} | {g['applied_per_s_slow']} |")
        lines += ["", "The twin node through an overload:", ""]
    lines += [
             "| run | variant | RSS calm (MB) | RSS overload (MB) | MB/min overload | RSS after (MB) | MB/min after "
             "| commands applied | deadline misses |", "|---|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(runs):
        g, s = r["growth"], r["summary"]
        lines.append(f"| {i + 1}{'' if g['valid'] else ' (no commands: excluded)'} | {r['variant']} | {g['calm_mb']:+.2f} | {g['overload_mb']:+.2f} | "
                     f"{g['overload_mb_per_min']:+.2f} | {g['after_mb']:+.2f} | {g['after_mb_per_min']:+.2f} | "
                     f"{s['accepted']} | {s['deadline_misses']} |")
    lines += ["", "Medians:", ""]
    for v in VARIANTS:
        rows = [r["growth"] for r in runs if r["variant"] == v]
        lines.append(f"- `{v}`: overload {med(rows, 'overload_mb_per_min'):+.2f} MB/min, after "
                     f"{med(rows, 'after_mb_per_min'):+.2f} MB/min ({len(rows)} runs)")
    if lat_runs:
        lines += ["", f"Calm runs ({a.latency_seconds:g} s each, no hogs, player at {a.latency_rate:g} Hz), "
                  "interleaved: latency in ms (node: a command's reception by the executor to its answer; "
                  "player: sent to answered).", "",
                  "| run | variant | node p50 | node p99 | player p50 | player p99 | deadline misses | "
                  "CPU beyond solver |", "|---|---|---|---|---|---|---|---|"]
        for i, r in enumerate(lat_runs):
            s = r["summary"]
            lines.append(f"| {i + 1}{'' if s['valid'] else ' (no commands: excluded)'} | {r['variant']} | {s['node_p50_ms']:.3f} | {s['node_p99_ms']:.3f} | "
                         f"{s['player_p50_ms']:.3f} | {s['player_p99_ms']:.3f} | {s['deadline_misses']} | "
                         f"{s['cpu_beyond_solver']:.2f} |")
        lines += ["", "Medians:", ""]
        for v in VARIANTS:
            rows = [r["summary"] for r in lat_runs if r["variant"] == v]
            lines.append(f"- `{v}`: node p50 {med(rows, 'node_p50_ms'):.3f} ms, p99 {med(rows, 'node_p99_ms'):.3f} ms; "
                         f"player p50 {med(rows, 'player_p50_ms'):.3f} ms, p99 {med(rows, 'player_p99_ms'):.3f} ms")
    lines += ["", "To reproduce: `.venv/bin/python benchmarks/node_overload_rss.py` (writes this file and "
              f"`{a.name}.json` with every RSS series)."]
    (DOCS / f"{a.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
