"""The node's parameters: one table (name, default, range, description), validated in one place.

``flexmb node`` flags and ``--ros-args -p name:=value`` both end up here; ``ros2 param describe``
shows the descriptions (the node declares every entry with a ``ParameterDescriptor``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from flexmb_core.errors import FlexmbError
from flexmb_io.topics import WORLD_FRAME


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: object
    description: str
    choices: tuple[str, ...] = ()
    low: float | None = None          # inclusive
    high: float | None = None         # inclusive
    read_only: bool = True            # fixed once the node runs


SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("scene", "", "scene YAML file of the mechanism (required)"),
    ParamSpec("mode", "realtime", "realtime: step at Δt paced by the wall clock; lockstep: one step per "
              "received command message (deterministic, for tests and replay)", choices=("realtime", "lockstep")),
    ParamSpec("dt", 0.0, "time step Δt (s); 0 = the scene's solver.dt", low=0.0, high=1.0),
    ParamSpec("integrator", "", "override solver.integrator: newmark | generalized_alpha | chung_hulbert "
              "('' = the scene's)", choices=("", "newmark", "generalized_alpha", "chung_hulbert")),
    ParamSpec("publish_rate", 100.0, "rate (Hz of simulated time) of /joint_states, actuator states, pose, "
              "status (joint states and status also follow every new command: publish_on_command; /clock: "
              "clock_rate)",
              low=1.0, high=10000.0, read_only=False),
    ParamSpec("shape_rate", 30.0, "rate (Hz) of ~/shape (member polylines, shell triangles); 0 disables", low=0.0,
              high=1000.0, read_only=False),
    ParamSpec("publish_on_command", True, "also publish joint states and status right after the first step "
              "that uses a new command (low command→state latency at any publish_rate)", read_only=False),
    ParamSpec("command_source", "external", "external: the command topics drive the actuators (held at their "
              "start lengths until the first command); scene: the scene's own commands", choices=("external", "scene")),
    ParamSpec("command_timeout", 0.5, "s without a command before the timeout behaviour starts (realtime)",
              low=1e-6, high=1e9),
    ParamSpec("command_timeout_behaviour", "hold", "hold: keep the last lengths; ramp_to_rest: ramp smoothly "
              "back to the start lengths", choices=("hold", "ramp_to_rest")),
    ParamSpec("ramp_time", 2.0, "duration of ramp_to_rest (s)", low=1e-6, high=1e6),
    ParamSpec("stale_after", 1.0, "reject stamped commands older than the twin's time by more than this (s)",
              low=1e-6, high=1e9),
    ParamSpec("max_lead", 1.0, "reject stamped commands ahead of the twin's time by more than this (s)",
              low=1e-6, high=1e9),
    ParamSpec("command_hold", "smooth", "how a command stream becomes motion: smooth (default): each new length "
              "is reached over the observed command period by a cubic Hermite, continuous in length and rate "
              "(rates from the command, else from the last three samples); ramp: a linear ramp, continuous in length; "
              "step: each command applies from the next step (the staircase of earlier versions)",
              choices=("smooth", "ramp", "step")),
    ParamSpec("max_command_rate", 10.0, "commanded rates (m/s) beyond this are rejected, for actuators without a "
              "servo (a servo's max_rate is their limit)", low=1e-9, high=1e6),
    ParamSpec("max_command_accel", 50.0, "most acceleration (m/s²) of the commanded length while the smooth hold "
              "joins a new command: a join that would need more is lengthened (a late stamp, a jumped clock, a "
              "step is reached over a time a real actuator could); 1e12 makes it unbounded", low=1e-6, high=1e12),
    ParamSpec("max_trajectory_points", 10000, "joint trajectories with more points are rejected", low=1,
              high=10_000_000),
    ParamSpec("joint_command_stamps", False, "false: ~/joint_commands (JointState) apply on arrival, their stamp "
              "ignored (topic_based_ros2_control stamps with its controller manager's clock); true: their stamps "
              "are checked and used as ~/actuator_commands' are"),
    ParamSpec("qos_depth", 10, "history depth of every publisher and subscription (a qos_overrides.<topic>."
              "publisher|subscription.depth parameter overrides it per topic)", low=1, high=100000),
    ParamSpec("publish_clock", True, "publish /clock with the simulated time (the node owns time)"),
    ParamSpec("clock_rate", 100.0, "rate (Hz of simulated time) of /clock, independent of publish_rate",
              low=1.0, high=100000.0, read_only=False),
    ParamSpec("world_frame", WORLD_FRAME, "frame_id of every header and parent frame of every transform (used as "
              "given, without frame_prefix)"),
    ParamSpec("frame_prefix", "auto", "prepended to the frames the twin names (its platforms, the /tf child "
              "frames); auto: the node's namespace without its leading '/' plus '/' ('robot1/' under /robot1, "
              "nothing at the root); any other string is used as given ('' for none)"),
    ParamSpec("autostart", True, "configure and activate the (managed) node at start; false: it starts "
              "unconfigured and waits for lifecycle transitions (flexmb node --lifecycle)"),
    ParamSpec("duration", 0.0, "stop after this much simulated time (s); 0 = run until shutdown", low=0.0,
              high=1e9),
    ParamSpec("idle_timeout", 0.0, "lockstep: stop after this many wall seconds without a command once "
              "commands have started; 0 = never", low=0.0, high=1e9),
    ParamSpec("max_lag", 0.1, "realtime: when the twin is this far behind the wall clock (s), re-anchor "
              "the schedule (counted as an overrun) instead of rushing to catch up", low=1e-3, high=1e6),
    ParamSpec("step_margin", 4.0e-4, "realtime: a step without a waiting command starts this long before its "
              "deadline (s); a command starts its step at once", low=0.0, high=1.0),
    ParamSpec("step_margin_auto", True, "realtime: widen step_margin to the step's own p99.9 wall time over "
              "the last second plus 0.2 ms (at most 4 Δt, and 4 Δt until 250 steps are measured; step_margin is "
              "then the least margin), so that steps that take longer (a tangent refresh, the first steps) still "
              "end before their deadline; false keeps step_margin"),
    ParamSpec("cpu_affinity", "", "realtime: comma-separated CPU ids for the stepping thread ('' = any CPU)"),
    ParamSpec("rt_priority", -1, "realtime: SCHED_FIFO priority of the stepping thread (1-99; 0 = the normal "
              "scheduler; -1 = 20 where the OS allows it, else the normal scheduler, said once at INFO level); an "
              "explicit priority the OS refuses (no CAP_SYS_NICE or rtprio limit) gives a warning", low=-1, high=99),
    ParamSpec("rt_threads", "stepping", "realtime: which threads rt_priority puts on SCHED_FIFO: stepping (default): "
              "the stepping thread alone; node: also the node's other threads that take the GIL (the executor, the "
              "publisher), one priority below it, so that no other process preempts a thread the stepping thread "
              "waits for (fewer missed deadlines on a busy machine, a longer latency tail on an idle one)",
              choices=("stepping", "node")),
    ParamSpec("cpu_dma_latency", -1, "realtime: a PM QoS request on the CPUs' idle states while the node runs "
              "(µs of exit latency allowed, written to /dev/cpu_dma_latency; 0 = the CPUs poll when idle instead of "
              "halting); -1 (default) = none. Shortens wake-ups on a machine to itself; on a shared virtual machine "
              "the hypervisor then preempts the busy CPUs for milliseconds (more missed deadlines, README). Refused "
              "(no permission): a warning", low=-1, high=1_000_000),
    ParamSpec("diagnostics_rate", 1.0, "rate (Hz of wall time) of /diagnostics; 0 disables", low=0.0, high=100.0),
    ParamSpec("record", "", "record inputs and outputs to this rosbag2/MCAP directory ('' = none)"),
    ParamSpec("rrd", "", "log the twin to this rerun .rrd file ('' = none)"),
    ParamSpec("summary_json", "", "write the run summary (JSON) here on exit ('' = none)"),
    ParamSpec("log_throttle", 1.0, "minimum interval between two identical warnings (s)", low=0.0, high=3600.0,
              read_only=False),
)
BY_NAME = {s.name: s for s in SPECS}


@dataclass
class NodeParams:
    scene: str = ""
    mode: str = "realtime"
    dt: float = 0.0
    integrator: str = ""
    publish_rate: float = 100.0
    shape_rate: float = 30.0
    publish_on_command: bool = True
    command_source: str = "external"
    command_timeout: float = 0.5
    command_timeout_behaviour: str = "hold"
    ramp_time: float = 2.0
    stale_after: float = 1.0
    max_lead: float = 1.0
    command_hold: str = "smooth"
    max_command_rate: float = 10.0
    max_command_accel: float = 50.0
    max_trajectory_points: int = 10000
    joint_command_stamps: bool = False
    qos_depth: int = 10
    publish_clock: bool = True
    clock_rate: float = 100.0
    world_frame: str = WORLD_FRAME
    frame_prefix: str = "auto"
    autostart: bool = True
    duration: float = 0.0
    idle_timeout: float = 0.0
    max_lag: float = 0.1
    step_margin: float = 4.0e-4
    step_margin_auto: bool = True
    cpu_affinity: str = ""
    rt_priority: int = -1
    rt_threads: str = "stepping"
    cpu_dma_latency: int = -1
    diagnostics_rate: float = 1.0
    record: str = ""
    rrd: str = ""
    summary_json: str = ""
    log_throttle: float = 1.0

    @classmethod
    def from_values(cls, values: dict) -> "NodeParams":
        """Validated parameters; :class:`FlexmbError` names the parameter, value and expectation."""
        out = cls()
        for f in fields(cls):
            if f.name in values:
                setattr(out, f.name, check(f.name, values[f.name]))
        if not out.scene:
            raise FlexmbError("parameter 'scene': required (a scene YAML file), got ''")
        return out


def check(name: str, value):
    """``value`` converted to the parameter's type, or :class:`FlexmbError`."""
    spec = BY_NAME.get(name)
    if spec is None:
        raise FlexmbError(f"unknown parameter '{name}'; known: {sorted(BY_NAME)}")
    kind = type(spec.default)
    if kind is bool:
        if not isinstance(value, bool):
            raise FlexmbError(f"parameter '{name}': expected true or false, got {value!r}")
    elif kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise FlexmbError(f"parameter '{name}': expected an integer, got {value!r}")
    elif kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise FlexmbError(f"parameter '{name}': expected a finite number, got {value!r}")
        value = float(value)
    elif not isinstance(value, str):
        raise FlexmbError(f"parameter '{name}': expected a string, got {value!r}")
    if spec.choices and value not in spec.choices:
        raise FlexmbError(f"parameter '{name}': expected one of {list(spec.choices)}, got {value!r}")
    if spec.low is not None and value < spec.low or spec.high is not None and value > spec.high:
        raise FlexmbError(f"parameter '{name}': expected a value in [{spec.low}, {spec.high}], got {value!r}")
    if name in _FRAMES:
        _check_frame(name, value)
    return value


_FRAMES = ("world_frame", "frame_prefix")


def _check_frame(name: str, value: str) -> None:
    """tf2 frame ids: no leading '/', no whitespace; the world frame not empty."""
    if (name == "world_frame" and not value) or value.startswith("/") or any(c.isspace() for c in value):
        raise FlexmbError(f"parameter '{name}': expected a tf2 frame {'prefix' if name == 'frame_prefix' else 'id'} "
                          f"(no leading '/', no spaces{', not empty' if name == 'world_frame' else ''}), "
                          f"got {value[:40]!r}")
