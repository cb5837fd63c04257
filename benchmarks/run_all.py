"""Run every benchmark and regenerate docs/benchmarks/ (``make bench``)."""

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = ["b1_cantilever.py", "stewart_platform.py", "work_precision.py", "bench_linear_solvers.py",
              "node_latency.py",   # work_precision.py = `flexmb bench` (docs/benchmarks/workprecision.md)
              "shell_cost.py"]     # docs/benchmarks/shell.md

if __name__ == "__main__":
    for b in BENCHMARKS:
        print(f"== {b}", flush=True)
        subprocess.run([sys.executable, str(HERE / b)], check=True)
