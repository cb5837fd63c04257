"""The node's hot path: rclpy messages filled straight from a sample, one reused object per topic.

The generic dict → message conversion (:func:`ros2_node.convert.to_ros`) costs ~80 µs a message,
too much inside a 1 ms step; these fillers cost a few µs. They must say exactly what
:mod:`flexmb_io.messages` says (the recordings use those dicts): a test compares the two field by
field.
"""

from __future__ import annotations

from flexmb_core.report import TwinSample
from flexmb_io import messages as M
from flexmb_io.shells import ShellShapes

from .convert import message_class


def _set_stamp(stamp, t: float) -> None:
    ns = int(round(t * 1e9))
    stamp.sec = ns // 1_000_000_000
    stamp.nanosec = ns % 1_000_000_000


def _set_pose(pose, position, wxyz) -> None:
    pose.position.x, pose.position.y, pose.position.z = float(position[0]), float(position[1]), float(position[2])
    o = pose.orientation
    o.w, o.x, o.y, o.z = float(wxyz[0]), float(wxyz[1]), float(wxyz[2]), float(wxyz[3])


class LiveMessages:
    """Reusable messages for one twin (publishing serializes at once, so reuse is safe)."""

    def __init__(self, sample: TwinSample, frames: M.Frames = M.DEFAULT_FRAMES):
        self.frames = frames
        world = frames.world
        JointState = message_class("sensor_msgs/msg/JointState")
        ActuatorState = message_class("flexmb_msgs/msg/ActuatorState")
        PoseStamped = message_class("geometry_msgs/msg/PoseStamped")
        TwinStatus = message_class("flexmb_msgs/msg/TwinStatus")
        Clock = message_class("rosgraph_msgs/msg/Clock")
        self.joint_state = JointState()
        self.joint_state.header.frame_id = world
        self.joint_state.name = list(sample.actuator_names) + list(sample.joint_names)
        self._zero_efforts = [0.0] * len(sample.joint_names)
        self.actuator_state = ActuatorState()
        self.actuator_state.header.frame_id = world
        self.actuator_state.names = list(sample.actuator_names)
        self.poses = [PoseStamped() for _ in sample.poses]
        for p in self.poses:
            p.header.frame_id = world
        self.status_msg = TwinStatus()
        self.status_msg.header.frame_id = world
        self.clock_msg = Clock()
        self.tf_msg = None
        try:
            TFMessage = message_class("tf2_msgs/msg/TFMessage")
            TransformStamped = message_class("geometry_msgs/msg/TransformStamped")
            self.tf_msg = TFMessage()
            self.tf_msg.transforms = [TransformStamped() for _ in sample.poses]
            for tr, p in zip(self.tf_msg.transforms, sample.poses):
                tr.header.frame_id = world
                tr.child_frame_id = frames.child(p.name)
        except ModuleNotFoundError:
            pass

    def fill_joint_state(self, s: TwinSample):
        m = self.joint_state
        _set_stamp(m.header.stamp, s.t)
        m.position = s.actuator_lengths.tolist() + s.joint_positions.tolist()
        m.velocity = s.actuator_velocities.tolist() + s.joint_velocities.tolist()
        m.effort = s.actuator_forces.tolist() + self._zero_efforts
        return m

    def fill_actuator_state(self, s: TwinSample):
        m = self.actuator_state
        _set_stamp(m.header.stamp, s.t)
        m.lengths = s.actuator_lengths.tolist()
        m.velocities = s.actuator_velocities.tolist()
        m.commanded_lengths = s.actuator_commands.tolist()
        m.axial_forces = s.actuator_forces.tolist()
        return m

    def fill_pose(self, s: TwinSample, i: int):
        m = self.poses[i]
        _set_stamp(m.header.stamp, s.t)
        _set_pose(m.pose, s.poses[i].position, s.poses[i].orientation_wxyz)
        return m

    def fill_tf(self, s: TwinSample):
        for tr, p in zip(self.tf_msg.transforms, s.poses):
            _set_stamp(tr.header.stamp, s.t)
            tr.transform.translation.x, tr.transform.translation.y, tr.transform.translation.z = (
                float(p.position[0]), float(p.position[1]), float(p.position[2]))
            r = tr.transform.rotation
            r.w, r.x, r.y, r.z = (float(v) for v in p.orientation_wxyz)
        return self.tf_msg

    def fill_status(self, s: TwinSample, timing: M.StatusTiming):
        m = self.status_msg
        _set_stamp(m.header.stamp, s.t)
        m.converged = bool(s.converged)
        m.newton_iterations = int(s.newton_iterations)
        m.residual = float(s.residual)
        m.kinetic_energy = float(s.kinetic_energy)
        m.strain_energy = float(s.strain_energy)
        m.total_energy = float(s.total_energy)
        m.step_wall_time = float(timing.step_wall_time)
        m.steps = int(timing.steps)
        m.deadline_misses = int(timing.deadline_misses)
        m.unconverged_steps = int(timing.unconverged_steps)
        m.real_time_factor = float(timing.real_time_factor)
        m.sim_time = float(s.t)
        m.substeps = int(s.substeps)
        m.message = timing.message or s.message
        _set_stamp(m.command_stamp, timing.command_stamp)
        m.command_latency = float(timing.command_latency)
        m.rejected_commands = int(timing.rejected_commands)
        m.command_age = float(timing.command_age)
        return m

    def make_shape(self, s: TwinSample, member_kinds, shells: ShellShapes | None = None) -> None:
        """The MarkerArray of :func:`flexmb_io.messages.shape`, built once: every marker and point
        object exists from here on and :meth:`fill_shape` only writes numbers into them."""
        MarkerArray = message_class("visualization_msgs/msg/MarkerArray")
        Marker = message_class("visualization_msgs/msg/Marker")
        Point = message_class("geometry_msgs/msg/Point")
        template = M.shape(s, member_kinds, shells)["markers"]
        self.shape_msg = MarkerArray()
        markers = []
        for d in template:
            mk = Marker()
            mk.header.frame_id = self.frames.world
            mk.ns, mk.id, mk.type, mk.action = d["ns"], d["id"], d["type"], d["action"]
            mk.pose.orientation.w = 1.0
            mk.scale.x, mk.scale.y, mk.scale.z = d["scale"]["x"], d["scale"]["y"], d["scale"]["z"]
            c = d["color"]
            mk.color.r, mk.color.g, mk.color.b, mk.color.a = c["r"], c["g"], c["b"], c["a"]
            mk.points = [Point() for _ in range(len(d["points"]))]
            markers.append(mk)
        self.shape_msg.markers = markers
        self._member_markers = markers[:len(s.member_points)]
        self._shell_markers = markers[len(s.member_points):]

    def fill_shape(self, s: TwinSample, member_kinds, shells: ShellShapes | None = None):
        """``~/shape`` at the sample's state (``shells`` read at the same state, as for
        :func:`flexmb_io.messages.shape`)."""
        if not hasattr(self, "shape_msg"):
            self.make_shape(s, member_kinds, shells)
        for mk, pts in zip(self._member_markers, s.member_points):
            _set_stamp(mk.header.stamp, s.t)
            for pt, (x, y, z) in zip(mk.points, pts.tolist()):
                pt.x, pt.y, pt.z = x, y, z
        for i, mk in enumerate(self._shell_markers):
            _set_stamp(mk.header.stamp, s.t)
            for pt, (x, y, z) in zip(mk.points, shells.vertices(i).tolist()):
                pt.x, pt.y, pt.z = x, y, z
        return self.shape_msg

    def fill_clock(self, t: float):
        _set_stamp(self.clock_msg.clock, t)
        return self.clock_msg
