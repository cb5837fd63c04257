"""Run every benchmark and regenerate docs/benchmarks/ (``make bench``)."""

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = ["b1_cantilever.py", "stewart_platform.py", "bench_linear_solvers.py", "node_latency.py"]

if __name__ == "__main__":
    for b in BENCHMARKS:
        print(f"== {b}", flush=True)
        subprocess.run([sys.executable, str(HERE / b)], check=True)
