"""Work-precision reports: the same as ``flexmb bench`` (``benchmarks/workprecision/``), as a script.

    .venv/bin/python benchmarks/work_precision.py [--case b1|spin_up|stewart|all] [--quick] [--out DIR]
"""

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))

from benchmarks.workprecision.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
