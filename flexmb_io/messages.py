"""A :class:`~flexmb_core.report.TwinSample` as ROS messages: the one form both the node and the
recordings use.

Each builder returns a message object of :mod:`flexmb_io.wire`'s type store (rosbags dataclasses,
numeric sequences as float64 arrays). The live node serializes it once and publishes and records the
same bytes; ``flexmb run --mcap`` records the bytes of the same builders, so live topics and
recordings cannot disagree. Time stamps are the simulated time (the node owns the clock and
publishes it on ``/clock``). Frame ids come from a :class:`Frames` (the node's ``world_frame`` and
``frame_prefix`` parameters; ``world`` and no prefix by default).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from flexmb_core.report import TwinSample

from .shells import ShellShapes
from .topics import WORLD_FRAME
from .wire import message_type as _type

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


def stamp(t: float):
    """``builtin_interfaces/Time`` of a time in seconds (t ≥ 0), rounded to the nanosecond."""
    ns = int(round(t * 1e9))
    return _type("builtin_interfaces/msg/Time")(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_seconds(st) -> float:
    """Seconds of a ``builtin_interfaces/Time`` or ``Duration``, given as dict or message."""
    if isinstance(st, dict):
        return st["sec"] + 1e-9 * st["nanosec"]
    return st.sec + 1e-9 * st.nanosec


def header(t: float, frame_id: str = WORLD_FRAME):
    return _type("std_msgs/msg/Header")(stamp=stamp(t), frame_id=frame_id)


def _f64(*parts) -> np.ndarray:
    return np.concatenate(parts).astype(np.float64, copy=False) if len(parts) > 1 else np.array(parts[0], np.float64)


def joint_state(s: TwinSample, frames: Frames = DEFAULT_FRAMES):
    """``sensor_msgs/JointState``: actuators (length, rate, axial force as effort), then the passive
    joints (angle, rate, zero effort: the joints are frictionless)."""
    return _type("sensor_msgs/msg/JointState")(
        header=header(s.t, frames.world), name=list(s.actuator_names) + list(s.joint_names),
        position=_f64(s.actuator_lengths, s.joint_positions), velocity=_f64(s.actuator_velocities, s.joint_velocities),
        effort=_f64(s.actuator_forces, np.zeros(len(s.joint_names))))


def actuator_state(s: TwinSample, frames: Frames = DEFAULT_FRAMES):
    """``flexmb_msgs/ActuatorState``."""
    return _type("flexmb_msgs/msg/ActuatorState")(
        header=header(s.t, frames.world), names=list(s.actuator_names), lengths=_f64(s.actuator_lengths),
        velocities=_f64(s.actuator_velocities), commanded_lengths=_f64(s.actuator_commands),
        axial_forces=_f64(s.actuator_forces))


def _point(position, kind: str = "geometry_msgs/msg/Point"):
    return _type(kind)(x=float(position[0]), y=float(position[1]), z=float(position[2]))


def _quaternion(wxyz):
    return _type("geometry_msgs/msg/Quaternion")(x=float(wxyz[1]), y=float(wxyz[2]), z=float(wxyz[3]), w=float(wxyz[0]))


def _pose(position, wxyz):
    return _type("geometry_msgs/msg/Pose")(position=_point(position), orientation=_quaternion(wxyz))


def platform_pose(s: TwinSample, index: int = 0, frames: Frames = DEFAULT_FRAMES):
    """``geometry_msgs/PoseStamped`` of the ``index``-th platform."""
    p = s.poses[index]
    return _type("geometry_msgs/msg/PoseStamped")(header=header(s.t, frames.world),
                                                  pose=_pose(p.position, p.orientation_wxyz))


def tf(s: TwinSample, frames: Frames = DEFAULT_FRAMES):
    """``tf2_msgs/TFMessage``: world → one frame per platform, named after its output (with the
    frame prefix)."""
    Transform, Stamped = _type("geometry_msgs/msg/Transform"), _type("geometry_msgs/msg/TransformStamped")
    out = [Stamped(header=header(s.t, frames.world), child_frame_id=frames.child(p.name),
                   transform=Transform(translation=_point(p.position, "geometry_msgs/msg/Vector3"),
                                       rotation=_quaternion(p.orientation_wxyz)))
           for p in s.poses]
    return _type("tf2_msgs/msg/TFMessage")(transforms=out)


@functools.lru_cache(maxsize=None)
def _marker_constants() -> tuple:
    """A marker's parts that never change (identity pose, zero lifetime, no texture or mesh), built once
    and shared by every marker: constructing them per marker tripled the cost of ``~/shape``."""
    from .wire import make

    zero = make("visualization_msgs/msg/Marker")
    zero.pose.orientation.w = 1.0
    return zero.pose, zero.lifetime, zero.texture, zero.mesh_file


def _marker(t: float, frames: Frames, ns: str, id_: int, type_: int, scale, rgba, points):
    pose, lifetime, texture, mesh_file = _marker_constants()
    Point = _type("geometry_msgs/msg/Point")
    r, g, b, a = (float(np.float32(c)) for c in rgba)          # float32 on the wire
    return _type("visualization_msgs/msg/Marker")(
        header=header(t, frames.world), ns=ns, id=id_, type=type_, action=MARKER_ADD, pose=pose,
        scale=_type("geometry_msgs/msg/Vector3")(x=float(scale[0]), y=float(scale[1]), z=float(scale[2])),
        color=_type("std_msgs/msg/ColorRGBA")(r=r, g=g, b=b, a=a), lifetime=lifetime, frame_locked=False,
        points=[Point(x=x, y=y, z=z) for x, y, z in np.asarray(points, dtype=np.float64).reshape(-1, 3).tolist()],
        colors=[], texture_resource="", texture=texture, uv_coordinates=[], text="", mesh_resource="",
        mesh_file=mesh_file, mesh_use_embedded_materials=False)


def shape(s: TwinSample, member_kinds: tuple[str, ...] | None = None, shells: ShellShapes | None = None,
          frames: Frames = DEFAULT_FRAMES):
    """``visualization_msgs/MarkerArray``: one LINE_STRIP per member through its nodes, then one
    TRIANGLE_LIST per shell (ns = name, id = position in the array).

    ``shells`` must have been read at the sample's state (:meth:`ShellShapes.read`, which
    :meth:`flexmb_io.twin.TwinRunner.sample` does); a shell's marker lists 3 points per flat
    triangle (:func:`flexmb_io.shells.shell_triangles`: 9 per cubic element), all in the marker's
    colour, with unit scale (RViz scales triangle-list points by it).
    """
    markers = []
    for k, (name, pts) in enumerate(zip(s.member_names, s.member_points)):
        rgba = MEMBER_RGBA.get(member_kinds[k] if member_kinds else "frame", MEMBER_RGBA["frame"])
        markers.append(_marker(s.t, frames, name, k, MARKER_LINE_STRIP, (s.member_widths[k], 0.0, 0.0), rgba, pts))
    if shells is not None:
        for i, name in enumerate(shells.names):
            markers.append(_marker(s.t, frames, name, len(markers), MARKER_TRIANGLE_LIST, (1.0, 1.0, 1.0),
                                   SHELL_RGBA, shells.vertices(i)))
    return _type("visualization_msgs/msg/MarkerArray")(markers=markers)


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


def status(s: TwinSample, timing: StatusTiming, frames: Frames = DEFAULT_FRAMES):
    """``flexmb_msgs/TwinStatus``."""
    return _type("flexmb_msgs/msg/TwinStatus")(
        header=header(s.t, frames.world), converged=bool(s.converged), newton_iterations=int(s.newton_iterations),
        residual=float(s.residual), kinetic_energy=float(s.kinetic_energy), strain_energy=float(s.strain_energy),
        total_energy=float(s.total_energy), step_wall_time=float(timing.step_wall_time), steps=int(timing.steps),
        deadline_misses=int(timing.deadline_misses), unconverged_steps=int(timing.unconverged_steps),
        real_time_factor=float(timing.real_time_factor), sim_time=float(s.t), substeps=int(s.substeps),
        message=timing.message or s.message, command_stamp=stamp(timing.command_stamp),
        command_latency=float(timing.command_latency), rejected_commands=int(timing.rejected_commands),
        command_age=float(timing.command_age))


def clock(t: float):
    """``rosgraph_msgs/Clock``."""
    return _type("rosgraph_msgs/msg/Clock")(clock=stamp(t))


def float64_array(values):
    """``std_msgs/Float64MultiArray`` with an empty layout (the ForwardCommandController form)."""
    layout = _type("std_msgs/msg/MultiArrayLayout")(dim=[], data_offset=0)
    return _type("std_msgs/msg/Float64MultiArray")(layout=layout, data=np.array(values, dtype=np.float64).reshape(-1))


def actuator_command(t: float, names, lengths, velocities=None):
    """``flexmb_msgs/ActuatorCommand``."""
    return _type("flexmb_msgs/msg/ActuatorCommand")(
        header=header(t), names=list(names), lengths=np.array(lengths, dtype=np.float64).reshape(-1),
        velocities=np.array([] if velocities is None else velocities, dtype=np.float64).reshape(-1))
