"""Helpers of the recording tests: the ``flexmb`` command as a subprocess (imported by name, so that
the name cannot collide with another directory's conftest)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FLEXMB = [sys.executable, "-m", "flexmb.cli"]
STEWART_BARS = "scenes/stewart_platform_bars.yaml"


def flexmb(*args, timeout: float = 300, **kw) -> subprocess.CompletedProcess:
    """Run ``flexmb ARGS`` from the repository root; output captured as text."""
    env = dict(os.environ)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))
    return subprocess.run(FLEXMB + [str(a) for a in args], capture_output=True, text=True, cwd=ROOT,
                          timeout=timeout, env=env, **kw)
