"""flexmb_core — total-Lagrangian positional FEM for flexible spatial mechanisms.

The core never imports ROS or rerun; adapters in ``ros2_node`` and ``flexmb_core.io`` do.
"""

__version__ = "0.1.0"
