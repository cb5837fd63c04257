"""Viewing the twin in rerun: a logger for live or offline samples, ``flexmb view`` for recordings,
``flexmb run --rrd`` and a headless PNG snapshot.

Nothing here imports rclpy. ``rerun`` is imported inside the functions and classes that use it,
so the command line (``flexmb_io.viz.cli``) loads where rerun is not installed.

Modules: :mod:`.layout` (what to draw, from a compiled model or from a recording), :mod:`.rerun_log`
(:class:`~flexmb_io.viz.rerun_log.TwinRerunLogger`), :mod:`.blueprint` (the default views),
:mod:`.recording` (reading a rosbag2 directory or a bare MCAP), :mod:`.view` (recording → logger),
:mod:`.hook` (the ``flexmb run --rrd`` hook), :mod:`.snapshot` (headless PNG), :mod:`.cli`.
"""
