"""flexmb's I/O layer: everything between the numerics and ROS that needs no rclpy.

- :mod:`.twin` — :class:`~flexmb_io.twin.TwinRunner`, the twin's runner (commands in, samples out),
  shared by the node, ``flexmb run --mcap``, replay and calibration; :mod:`.commands` — the command
  holds (numba); :mod:`.realtime` — the node's stepping thread (plain threads, no rclpy)
- :mod:`.messages` — the twin's outputs as messages, serialized once by :mod:`.wire` (rosbags);
  :mod:`.topics` — the topic table (names, types, QoS roles); :mod:`.shells` — shell surfaces as
  triangle meshes
- :mod:`.bag` — rosbag2/MCAP recording, reading, replay, calibration (``mcap``/``rosbags`` loaded lazily)
- :mod:`.viz` — rerun logging and viewing (``rerun`` loaded lazily)

Imports :mod:`flexmb_core`, never rclpy, :mod:`ros2_node` or :mod:`flexmb` (``tests/unit/test_layers.py``).
"""
