"""Drive a lockstep twin over DDS from this process and collect its ``/tf`` (tests of the ROS package).

:func:`drive_lockstep` sends ``n`` actuator-length commands one at a time, waits for the status that
answers each, and returns what came back, with the type and RIHS01 hash the ``/tf`` publisher
announces in the ROS graph.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

TWIN = "flexmb_twin"


@dataclass
class Answers:
    statuses: list = field(default_factory=list)
    actuator_states: list = field(default_factory=list)
    tf: list = field(default_factory=list)
    tf_publishers: list = field(default_factory=list)      # [(topic type, 'RIHS01_<hex>')]


def rihs01(type_hash) -> str:
    """rclpy's TypeHash as the 'RIHS01_<hex>' string of .json type descriptions and rosbags."""
    return f"RIHS{type_hash.version:02d}_{bytes(type_hash.value).hex()}"


def standard_tfmessage_hash() -> str:
    """RIHS01 hash of tf2_msgs/msg/TFMessage as ROS 2 ships it (rosbags' Jazzy type store)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY).hash_rihs01("tf2_msgs/msg/TFMessage")


def drive_lockstep(lengths0, n: int, *, dt: float, alive, log, timeout_up: float) -> Answers:
    """Command ``lengths0 + 1e-5 (k + 1)`` m for k < n to a lockstep twin named ``flexmb_twin``.

    ``alive()`` tells whether the twin's process still runs and ``log()`` returns its output (both
    for failure messages); ``timeout_up`` is how long the twin may take to come up (s).
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray
    from tf2_msgs.msg import TFMessage

    from flexmb_msgs.msg import ActuatorState, TwinStatus

    out = Answers()
    context = Context()
    rclpy.init(context=context, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("flexmb_package_test", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(Float64MultiArray, f"/{TWIN}/commands", qos)
    node.create_subscription(TwinStatus, f"/{TWIN}/status", out.statuses.append, qos)
    node.create_subscription(ActuatorState, f"/{TWIN}/actuator_states", out.actuator_states.append, qos)
    node.create_subscription(TFMessage, "/tf", out.tf.append, qos)

    def spin_until(predicate, timeout: float, what: str) -> None:
        t_end = time.monotonic() + timeout
        while not predicate():
            if not alive():
                raise AssertionError(f"the twin exited while waiting for {what}:\n{log()[-3000:]}")
            if time.monotonic() > t_end:
                raise AssertionError(f"timed out after {timeout} s waiting for {what}:\n{log()[-3000:]}")
            executor.spin_once(timeout_sec=0.02)

    try:
        spin_until(lambda: out.statuses and pub.get_subscription_count() > 0, timeout_up, "the twin to come up")
        for k in range(n):
            msg = Float64MultiArray()
            msg.data = [float(x) + 1e-5 * (k + 1) for x in lengths0]
            pub.publish(msg)
            spin_until(lambda: any(s.steps >= k + 1 for s in out.statuses), 30.0, f"the answer to command {k + 1}")
        t_end = n * dt
        spin_until(lambda: any(abs(s.sim_time - t_end) < 0.5 * dt for s in out.statuses) and out.tf
                   and any(abs(a.header.stamp.sec + 1e-9 * a.header.stamp.nanosec - t_end) < 0.5 * dt
                           for a in out.actuator_states), 10.0, "the last states and /tf")
        out.tf_publishers = [(i.topic_type, rihs01(i.topic_type_hash)) for i in node.get_publishers_info_by_topic("/tf")]
    finally:
        executor.shutdown()
        node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)
    return out
