"""flexmb_core — total-Lagrangian positional FEM for flexible spatial mechanisms.

The core never imports ROS, rerun, mcap or ``benchmarks/``; the adapters in ``flexmb_io`` (recordings,
rerun, the twin runner; no rclpy) and ``ros2_node`` (rclpy) do (``tests/unit/test_layers.py``).
"""

__version__ = "0.1.0"


def _fresh_numba_cache() -> None:
    # before any kernel is loaded from numba's cache (see flexmb_core.numba_cache)
    from .numba_cache import ensure_fresh

    ensure_fresh()


_fresh_numba_cache()
