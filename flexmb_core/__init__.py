"""flexmb_core — total-Lagrangian positional FEM for flexible spatial mechanisms.

The core never imports ROS or rerun; adapters in ``ros2_node`` and ``flexmb_core.io`` do.
"""

__version__ = "0.1.0"


def _fresh_numba_cache() -> None:
    # before any kernel is loaded from numba's cache (see flexmb_core.numba_cache)
    from .numba_cache import ensure_fresh

    ensure_fresh()


_fresh_numba_cache()
