"""Bare command streams over real DDS into a realtime twin (issue 12): the peak leg force, run by run.

The setup of ``tests/ros/test_command_stream_dds.py`` (its harness, ``tests/ros/dds_harness.py``):
a realtime node of the bar-leg Stewart twin (separate process, loopback, a random domain,
recording to MCAP) and a client in this process that samples the appendix law on its own clock at
``--rate`` and sends each sample as a bare ``Float64MultiArray``. The peak is the largest leg force
of the actuator states the node recorded (published at 200 Hz) while the stream ran, against the
smooth run's (the scene's own commands, offline). Each run also reports the twin's missed
deadlines, the commands the node recorded (the others were lost on the way) and the client's
samples sent more than two periods late (the test skips a run where either exceeds 5 %).

``--load-node-core``: a busy loop shares the node's core (the node's threads and the loop pinned to
CPU 1, this client to CPU 0), the case where the node takes commands late.

Writes docs/benchmarks/bare_stream_dds.{md,json} (``--name``).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bare_stream_dds.py [--rates 1000 100] [--runs 10 5]
        [--load-node-core] [--name bare_stream_dds]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "ros"))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

import numpy as np  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402
from flexmb_io import topics as T  # noqa: E402
from flexmb_io.bag.reader import BagReader  # noqa: E402

DOCS = ROOT / "docs" / "benchmarks"
SCENE = "scenes/stewart_platform_bars.yaml"
SPAN = 2.0          # s of the law streamed, as the test


def one_run(program: Simulator, rate: float, out: Path, load_node_core: bool) -> dict:
    """One node, one stream; the peak from the node's recording."""
    from dds_harness import NodeProcess, TwinClient
    from ros2_node.convert import message_class

    os.environ["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 200))
    summary = out.with_suffix(".json")
    node = NodeProcess([SCENE, "--mode", "realtime", "--publish-rate", "200", "--shape-rate", "0",
                        "--summary-json", str(summary), "--mcap", str(out)], dict(os.environ),
                       out.with_suffix(".log"))
    if load_node_core:        # the node's threads inherit its main thread's CPU set
        subprocess.run(["taskset", "-a", "-p", "-c", "1", str(node.proc.pid)], capture_output=True, check=True)
    client = TwinClient()
    clock = {"t": None}
    client.node.create_subscription(message_class(T.CLOCK.type), T.CLOCK.resolved("flexmb_twin"),
                                    lambda m: clock.__setitem__("t", m.clock.sec + 1e-9 * m.clock.nanosec), 100)
    late: list[float] = []
    try:
        client.wait_for_twin(node)
        client.spin_until(lambda: clock["t"] is not None, 30, "/clock", node)
        client.unsubscribe(T.JOINT_STATES, T.STATUS, T.PLATFORM_POSE, T.SHAPE, T.DIAGNOSTICS)
        late = client.stream_lengths(program.command_lengths, rate, SPAN)
        time.sleep(0.3)
    finally:
        client.close()
        node.stop()
    reader = BagReader(out)
    sent = [m.t for m in reader.messages({T.COMMANDS.resolved("flexmb_twin")})]
    t0, t1 = sent[0], sent[-1]
    peak = max(float(np.abs(np.array(m.decode().axial_forces)).max())
               for m in reader.messages({T.ACTUATOR_STATES.resolved("flexmb_twin")}) if t0 < m.t <= t1)
    s = json.loads(summary.read_text())
    return {"rate_hz": rate, "peak_N": peak, "deadline_misses": s["deadline_misses"], "steps": s["steps"],
            "commands_recorded": len(sent), "commands_sent": len(late),
            "client_late": int(sum(x > 2.0 / rate for x in late))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[1000.0, 100.0])
    ap.add_argument("--runs", type=int, nargs="+", default=[10, 5], help="runs per rate (one value: every rate)")
    ap.add_argument("--load-node-core", action="store_true")
    ap.add_argument("--name", default="bare_stream_dds")
    ap.add_argument("--keep", default=None, help="keep the node's recordings under this directory")
    args = ap.parse_args(argv)
    runs = args.runs * len(args.rates) if len(args.runs) == 1 else args.runs
    model = compile_scene(load_scene(str(ROOT / SCENE)))
    program = Simulator(model)
    from dds_harness import smooth_peak_force
    smooth = smooth_peak_force(model, SPAN)
    busy = None
    if args.load_node_core:
        os.sched_setaffinity(0, {0})
        busy = subprocess.Popen(["taskset", "-c", "1", "sh", "-c", "while :; do :; done"])
    rows = []
    try:
        with tempfile.TemporaryDirectory(prefix="flexmb_bare_stream_") as tmp:
            where = Path(args.keep or tmp)
            where.mkdir(parents=True, exist_ok=True)
            for rate, n in zip(args.rates, runs):
                for i in range(n):
                    rows.append(one_run(program, rate, where / f"r{int(rate)}_{i}", args.load_node_core))
                    print(json.dumps(rows[-1]), flush=True)
    finally:
        if busy is not None:
            busy.kill()
    meta = {"scene": SCENE, "span_s": SPAN, "smooth_peak_N": smooth, "load_node_core": args.load_node_core,
            "machine": platform.platform(), "cores": os.cpu_count(), "load_average_end": os.getloadavg(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    DOCS.mkdir(parents=True, exist_ok=True)
    (DOCS / f"{args.name}.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n")
    lines = [f"# Bare command streams over DDS (`benchmarks/bare_stream_dds.py`){' — node core loaded' if args.load_node_core else ''}",
             "", f"{meta['date']}, {meta['machine']}, {meta['cores']} cores. `{SCENE}`, realtime node, the appendix "
             f"law's first {SPAN:g} s as bare `Float64MultiArray` lengths; smooth run's peak **{smooth:.1f} N**"
             + ("; a busy loop on the node's core (node on CPU 1, client on CPU 0)" if args.load_node_core else "")
             + ".", "",
             "| rate (Hz) | peak (N) | / smooth | missed deadlines | commands recorded / sent | client samples > 2 periods late |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['rate_hz']:g} | {r['peak_N']:.1f} | {r['peak_N'] / smooth:.3f} | {r['deadline_misses']} / "
                     f"{r['steps']} | {r['commands_recorded']} / {r['commands_sent']} | {r['client_late']} |")
    for rate in args.rates:
        p = [r["peak_N"] for r in rows if r["rate_hz"] == rate]
        within = sum(abs(x - smooth) <= 0.1 * smooth for x in p)
        lines.append(f"\n{rate:g} Hz: {min(p):.1f}–{max(p):.1f} N, {within} of {len(p)} runs within 10 % of smooth.")
    (DOCS / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {DOCS / (args.name + '.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
