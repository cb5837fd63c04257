"""A :class:`~flexmb_core.report.TwinSample` as ROS messages, in plain dicts (no rclpy).

One dict per message, with the ROS field names: ``mcap_ros2`` encodes them straight into a
recording, and :func:`ros2_node.convert.to_ros` fills the rclpy message the live node publishes,
so live topics and recordings cannot disagree. Time stamps are the simulated time (the node owns
the clock and publishes it on ``/clock``). Frame ids come from a :class:`Frames` (the node's
``world_frame`` and ``frame_prefix`` parameters; ``world`` and no prefix by default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexmb_core.report import TwinSample

from .shells import ShellShapes
from .topics import WORLD_FRAME

MARKER_LINE_STRIP = 4
MARKER_TRIANGLE_LIST = 11
MARKER_ADD = 0
# member colours by kind, and the shells' (RViz markers and the rerun view use the same)
MEMBER_RGBA = {"actuator": (0.95, 0.55, 0.10, 1.0), "frame": (0.35, 0.55, 0.85, 1.0),
                "truss": (0.55, 0.75, 0.40, 1.0), "shell": (0.78, 0.80, 0.86, 1.0)}
SHELL_RGBA = MEMBER_RGBA["shell"]


@dataclass(frozen=True)
class Frames:
    """The frame ids of a twin's messages."""

    world: str = WORLD_FRAME     # frame_id of every header, parent of every transform
    prefix: str = ""             # prepended to each platform's frame (the tf child frames)

    def child(self, name: str) -> str:
        return self.prefix + name


DEFAULT_FRAMES = Frames()


def stamp(t: float) -> dict:
    """``builtin_interfaces/Time`` of a time in seconds (t ≥ 0), rounded to the nanosecond."""
    ns = int(round(t * 1e9))
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def stamp_seconds(st) -> float:
    """Seconds of a ``builtin_interfaces/Time`` or ``Duration``, given as dict or message."""
    if isinstance(st, dict):
        return st["sec"] + 1e-9 * st["nanosec"]
    return st.sec + 1e-9 * st.nanosec


def header(t: float, frame_id: str = WORLD_FRAME) -> dict:
    return {"stamp": stamp(t), "frame_id": frame_id}


def joint_state(s: TwinSample, frames: Frames = DEFAULT_FRAMES) -> dict:
    """``sensor_msgs/JointState``: actuators (length, rate, axial force as effort), then the passive
    joints (angle, rate, zero effort: the joints are frictionless)."""
    nj = len(s.joint_names)
    return {"header": header(s.t, frames.world),
            "name": list(s.actuator_names) + list(s.joint_names),
            "position": s.actuator_lengths.tolist() + s.joint_positions.tolist(),
            "velocity": s.actuator_velocities.tolist() + s.joint_velocities.tolist(),
            "effort": s.actuator_forces.tolist() + [0.0] * nj}


def actuator_state(s: TwinSample, frames: Frames = DEFAULT_FRAMES) -> dict:
    """``flexmb_msgs/ActuatorState``."""
    return {"header": header(s.t, frames.world), "names": list(s.actuator_names),
            "lengths": s.actuator_lengths.tolist(), "velocities": s.actuator_velocities.tolist(),
            "commanded_lengths": s.actuator_commands.tolist(), "axial_forces": s.actuator_forces.tolist()}


def _pose(position: np.ndarray, wxyz: np.ndarray) -> dict:
    return {"position": {"x": float(position[0]), "y": float(position[1]), "z": float(position[2])},
            "orientation": {"x": float(wxyz[1]), "y": float(wxyz[2]), "z": float(wxyz[3]), "w": float(wxyz[0])}}


def platform_pose(s: TwinSample, index: int = 0, frames: Frames = DEFAULT_FRAMES) -> dict:
    """``geometry_msgs/PoseStamped`` of the ``index``-th platform."""
    p = s.poses[index]
    return {"header": header(s.t, frames.world), "pose": _pose(p.position, p.orientation_wxyz)}


def tf(s: TwinSample, frames: Frames = DEFAULT_FRAMES) -> dict:
    """``tf2_msgs/TFMessage``: world → one frame per platform, named after its output (with the
    frame prefix)."""
    out = []
    for p in s.poses:
        pose = _pose(p.position, p.orientation_wxyz)
        out.append({"header": header(s.t, frames.world), "child_frame_id": frames.child(p.name),
                    "transform": {"translation": pose["position"], "rotation": pose["orientation"]}})
    return {"transforms": out}


def shape(s: TwinSample, member_kinds: tuple[str, ...] | None = None, shells: ShellShapes | None = None,
          frames: Frames = DEFAULT_FRAMES) -> dict:
    """``visualization_msgs/MarkerArray``: one LINE_STRIP per member through its nodes, then one
    TRIANGLE_LIST per shell (ns = name, id = position in the array).

    ``shells`` must have been read at the sample's state (:meth:`ShellShapes.read`, which
    :meth:`flexmb_io.twin.TwinRunner.sample` does); a shell's marker lists 3 points per flat
    triangle (:func:`flexmb_io.shells.shell_triangles`: 9 per cubic element), all in the marker's
    colour, with unit scale (RViz scales triangle-list points by it).
    """
    markers = []
    for k, (name, pts) in enumerate(zip(s.member_names, s.member_points)):
        r, g, b, a = MEMBER_RGBA.get(member_kinds[k] if member_kinds else "frame", MEMBER_RGBA["frame"])
        markers.append({
            "header": header(s.t, frames.world), "ns": name, "id": k, "type": MARKER_LINE_STRIP, "action": MARKER_ADD,
            "pose": _pose(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])),
            "scale": {"x": float(s.member_widths[k]), "y": 0.0, "z": 0.0},
            "color": {"r": r, "g": g, "b": b, "a": a},
            "points": [{"x": float(x), "y": float(y), "z": float(z)} for x, y, z in pts],
        })
    if shells is not None:
        r, g, b, a = SHELL_RGBA
        for i, name in enumerate(shells.names):
            markers.append({
                "header": header(s.t, frames.world), "ns": name, "id": len(markers), "type": MARKER_TRIANGLE_LIST,
                "action": MARKER_ADD, "pose": _pose(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])),
                "scale": {"x": 1.0, "y": 1.0, "z": 1.0},
                "color": {"r": r, "g": g, "b": b, "a": a},
                "points": [{"x": x, "y": y, "z": z} for x, y, z in shells.vertices(i).tolist()],
            })
    return {"markers": markers}


@dataclass
class StatusTiming:
    """What the node (or the offline runner) adds to a sample's solver health in ``TwinStatus``."""

    step_wall_time: float = 0.0       # s
    steps: int = 0
    deadline_misses: int = 0
    unconverged_steps: int = 0
    real_time_factor: float = 0.0
    command_stamp: float = 0.0        # s, header stamp of the newest command used
    command_latency: float = 0.0      # s, reception of the newest command → first state using it
    rejected_commands: int = 0
    command_age: float = 0.0          # s, wall time since the newest accepted command arrived
    message: str = ""                 # overrides the solver's message when set


def status(s: TwinSample, timing: StatusTiming, frames: Frames = DEFAULT_FRAMES) -> dict:
    """``flexmb_msgs/TwinStatus``."""
    return {"header": header(s.t, frames.world), "converged": bool(s.converged),
            "newton_iterations": int(s.newton_iterations), "residual": float(s.residual),
            "kinetic_energy": float(s.kinetic_energy), "strain_energy": float(s.strain_energy),
            "total_energy": float(s.total_energy), "step_wall_time": float(timing.step_wall_time),
            "steps": int(timing.steps), "deadline_misses": int(timing.deadline_misses),
            "unconverged_steps": int(timing.unconverged_steps),
            "real_time_factor": float(timing.real_time_factor), "sim_time": float(s.t),
            "substeps": int(s.substeps), "message": timing.message or s.message,
            "command_stamp": stamp(timing.command_stamp), "command_latency": float(timing.command_latency),
            "rejected_commands": int(timing.rejected_commands), "command_age": float(timing.command_age)}


def clock(t: float) -> dict:
    """``rosgraph_msgs/Clock``."""
    return {"clock": stamp(t)}


def float64_array(values) -> dict:
    """``std_msgs/Float64MultiArray`` with an empty layout (the ForwardCommandController form)."""
    return {"layout": {"dim": [], "data_offset": 0}, "data": [float(v) for v in values]}


def actuator_command(t: float, names, lengths, velocities=None) -> dict:
    """``flexmb_msgs/ActuatorCommand``."""
    return {"header": header(t), "names": list(names), "lengths": [float(v) for v in lengths],
            "velocities": [] if velocities is None else [float(v) for v in velocities]}
