"""How late this host wakes a real-time thread: the floor under the twin's deadline misses.

A thread on SCHED_FIFO (where the OS allows it; the twin's stepping thread uses priority 20 as
well), timer slack 1 µs, sleeps to absolute ticks of ``period`` with ``threading.Event.wait`` —
the way :class:`flexmb_io.realtime.Stepper` waits — and records how late each wake-up is. A wake-up
later than the twin's ``step_margin`` minus its step time is a deadline miss no code in the twin
can prevent; on a virtual machine the hypervisor's preemptions set that floor.

    .venv/bin/python benchmarks/host_jitter.py [--seconds 60] [--period 0.001]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flexmb_io.realtime import timer_slack, apply_thread_scheduling  # noqa: E402

THRESHOLDS_S = (3e-4, 6e-4, 1e-3, 2e-3)


def measure(seconds: float, period: float = 1e-3) -> dict:
    """Wake-up lateness of a SCHED_FIFO thread on absolute ticks; counts over thresholds, max (s)."""
    n = int(seconds / period)
    late = np.empty(n)
    out: dict = {}

    def run() -> None:
        timer_slack(1000)
        _, notes = apply_thread_scheduling((), -1)
        out["scheduling"] = notes[0] if notes else "normal scheduler"
        ev, clock = threading.Event(), time.perf_counter
        t0 = clock()
        for i in range(n):
            target = t0 + (i + 1) * period
            ev.wait(max(0.0, target - clock()))
            late[i] = clock() - target

    th = threading.Thread(target=run, name="jitter")
    th.start()
    th.join()
    out |= {"seconds": seconds, "period_s": period, "wakes": n,
            "late_p50_s": float(np.percentile(late, 50)), "late_p99_s": float(np.percentile(late, 99)),
            "late_p999_s": float(np.percentile(late, 99.9)), "late_max_s": float(late.max())}
    out["late_over"] = {f"{1e3 * t:g} ms": int((late > t).sum()) for t in THRESHOLDS_S}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--period", type=float, default=1e-3)
    a = ap.parse_args()
    print(json.dumps(measure(a.seconds, a.period) | {"load_avg": os.getloadavg()}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
