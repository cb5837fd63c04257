"""The twin's ROS interface: topic names and message types (a contract; see README "The ROS 2 twin node").

Names follow ROS 2's rules, so a namespace (``--ros-args -r __ns:=/robot1``) and remappings
(``-r joint_states:=js``) apply to them: names starting with ``~/`` are private to the node and
resolve to ``<namespace>/<node name>/...`` (default node name ``flexmb_twin``); relative names
(``joint_states``) resolve to ``<namespace>/...``; absolute names stay global — ``/clock`` (one
simulated time per ROS graph; a second twin in the same graph sets ``publish_clock: false`` or
remaps it), ``/tf`` (one transform tree; twins are told apart by the ``frame_prefix`` of their
frames, as with ``robot_state_publisher``) and ``/diagnostics`` (what ``diagnostic_aggregator``
reads; the entries carry the node's name). The live node lets rclpy resolve the names and records
the resolved ones; without a namespace or remapping they are :meth:`Topic.resolved`, which offline
recordings (``flexmb run --mcap``) use, so the two kinds of bag are interchangeable.
"""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_NODE_NAME = "flexmb_twin"
WORLD_FRAME = "world"

# input topic → the ``topic_kind`` of :func:`flexmb_io.twin.apply_message`
KINDS = {"~/commands": "commands", "~/actuator_commands": "actuator_commands",
         "~/joint_trajectory": "joint_trajectory", "~/joint_commands": "joint_commands"}


@dataclass(frozen=True)
class Topic:
    name: str          # as declared (may start with "~/")
    type: str          # ROS type, "pkg/msg/Type"
    direction: str     # "in" (the twin subscribes) | "out" (the twin publishes)
    doc: str

    def resolved(self, node_name: str = DEFAULT_NODE_NAME, namespace: str = "/") -> str:
        """The fully qualified name for a node ``node_name`` in ``namespace`` (no remapping)."""
        ns = namespace.rstrip("/")
        if self.name.startswith("~/"):
            return f"{ns}/{node_name}/{self.name[2:]}"
        return self.name if self.name.startswith("/") else f"{ns}/{self.name}"


# --- inputs -------------------------------------------------------------------------------------
COMMANDS = Topic("~/commands", "std_msgs/msg/Float64MultiArray", "in",
                 "actuator lengths (m), one per actuator in scene order (ForwardCommandController)")
ACTUATOR_COMMANDS = Topic("~/actuator_commands", "flexmb_msgs/msg/ActuatorCommand", "in",
                          "named actuator lengths (m), optional rates (m/s), stamped")
TRAJECTORY = Topic("~/joint_trajectory", "trajectory_msgs/msg/JointTrajectory", "in",
                   "actuator length trajectory, interpolated in time (cubic with velocities, else linear)")
JOINT_COMMANDS = Topic("~/joint_commands", "sensor_msgs/msg/JointState", "in",
                       "named actuator lengths as JointState.position (m), optional velocity (m/s): the "
                       "topic_based_ros2_control convention")

# --- outputs ------------------------------------------------------------------------------------
JOINT_STATES = Topic("joint_states", "sensor_msgs/msg/JointState", "out",
                     "actuators: length (m), rate (m/s), axial force as effort (N); passive joints: angle (rad)")
ACTUATOR_STATES = Topic("~/actuator_states", "flexmb_msgs/msg/ActuatorState", "out",
                        "actuator lengths, rates, commanded lengths, axial forces")
PLATFORM_POSE = Topic("~/platform_pose", "geometry_msgs/msg/PoseStamped", "out",
                      "centroid and orientation of the scene's first platform_pose output")
SHAPE = Topic("~/shape", "visualization_msgs/msg/MarkerArray", "out",
              "deformed members as LINE_STRIP markers, shells as TRIANGLE_LIST (node positions, m)")
STATUS = Topic("~/status", "flexmb_msgs/msg/TwinStatus", "out",
               "solver health of the last step, timing, deadline misses, rejected commands")
CLOCK = Topic("/clock", "rosgraph_msgs/msg/Clock", "out", "simulated time, when the node owns time")
TF = Topic("/tf", "tf2_msgs/msg/TFMessage", "out",
           "world → platform frames (recorded always; published live where tf2_msgs is installed)")
DIAGNOSTICS = Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", "out",
                    "solver health, deadline misses, command rejections (live only, at diagnostics_rate)")

INPUTS = (COMMANDS, ACTUATOR_COMMANDS, TRAJECTORY, JOINT_COMMANDS)
OUTPUTS = (JOINT_STATES, ACTUATOR_STATES, PLATFORM_POSE, SHAPE, STATUS, CLOCK, TF, DIAGNOSTICS)
ALL = INPUTS + OUTPUTS


def pose_topic(output_name: str, index: int) -> Topic:
    """Topic of the ``index``-th ``platform_pose`` output: the first is ``~/platform_pose``,
    further ones ``~/<output name>/platform_pose`` (every pose topic ends in ``platform_pose``)."""
    if index == 0:
        return PLATFORM_POSE
    return Topic(f"~/{output_name}/platform_pose", PLATFORM_POSE.type, "out", PLATFORM_POSE.doc)
