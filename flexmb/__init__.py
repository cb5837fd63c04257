"""flexmb's command line: the package that assembles the layers' verbs (``flexmb = flexmb.cli:main``).

The layers, each importing only those before it (``tests/unit/test_layers.py`` checks it):

1. :mod:`flexmb_core` — the numerics (scene, model, kernels, solvers, integrators); never imports ROS,
   rerun, mcap or ``benchmarks/``;
2. :mod:`flexmb_io` — recordings (rosbag2/MCAP), rerun viewing, the twin runner and its command holds,
   the messages and the topic table; no rclpy;
3. :mod:`ros2_node` — the rclpy node, the command player, live replay and the demo;
4. this package — :mod:`flexmb.cli` (the ``flexmb`` command) and :mod:`flexmb.ros_entry` (the ROS
   package's ``flexmb_node``/``flexmb_player`` executables).
"""
