"""Recording, reading and replaying rosbag2-compatible MCAP (no rclpy needed).

- :mod:`.recorder` — :class:`~.recorder.BagRecorder`: the twin's messages (or their CDR bytes) → a bag
- :mod:`.run_hook` — ``flexmb run SCENE --mcap OUT``
- :mod:`.replay` — ``flexmb replay BAG``: lockstep re-run and per-field comparison (:mod:`.compare`,
  tolerances in :mod:`.tolerances`)
- :mod:`.reader` — truncation-tolerant reading and ``flexmb bag recover``; :mod:`.info` — ``flexmb bag info``
- :mod:`.regenerate` — ``flexmb bag regenerate`` (``bags/manifest.yaml``)
- :mod:`.writer`, :mod:`.rosbag2` — the file layout and ``metadata.yaml``; messages, their CDR bytes,
  ``ros2msg`` schemas and type hashes come from :mod:`flexmb_io.wire` (rosbags' type store)
"""
