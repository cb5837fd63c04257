"""Test-wide environment: single-threaded BLAS, a writable numba cache, DDS kept on localhost; the
local Dask cluster of the study tests."""

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.fixture(scope="module")
def client():
    """The local cluster every study verb starts with ``--workers 2`` (flexmb_core.study.cluster.connect:
    two worker processes, one thread each, on 127.0.0.1), one per test module."""
    pytest.importorskip("distributed")
    from flexmb_core.study.cluster import connect

    with connect(None, 2) as c:
        yield c
