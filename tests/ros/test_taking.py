"""``take_waiting`` over real DDS: it empties a keep-last history oldest first, and the events
executor's entries for the messages it took then find nothing, so no callback runs for them (the
node's command taking and the player's status callback rely on both; ros2_node/taking.py)."""

from __future__ import annotations

import os
import time

import pytest

rclpy = pytest.importorskip("rclpy")


def _until(predicate, spin, timeout: float, what: str) -> None:
    t_end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < t_end, f"timed out waiting for {what}"
        spin()


def test_take_waiting_empties_the_history_and_the_stale_entries_run_no_callback(dds_env):
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray

    from ros2_node.taking import take_waiting

    context = Context()
    rclpy.init(context=context, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
    try:
        node = rclpy.create_node("taking_test", context=context)
        depth = 5
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        pub = node.create_publisher(Float64MultiArray, "taking_test", QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE))
        called: list[float] = []
        sub = node.create_subscription(Float64MultiArray, "taking_test", lambda m: called.append(m.data[0]), qos)
        executor = EventsExecutor(context=context)
        executor.add_node(node)
        _until(lambda: pub.get_subscription_count() > 0, lambda: executor.spin_once(timeout_sec=0.02), 10.0,
               "the subscription to match")

        # one message through the executor: delivery works, and tells how long it takes here
        pub.publish(Float64MultiArray(data=[-1.0]))
        _until(lambda: called, lambda: executor.spin_once(timeout_sec=0.02), 10.0, "the first message")
        assert called == [-1.0]

        n = 40
        for i in range(n):
            pub.publish(Float64MultiArray(data=[float(i)]))
        time.sleep(0.5)                                 # delivered into the history, not yet spun
        taken = take_waiting(sub)
        assert [m.data[0] for m in taken] == [float(i) for i in range(n - depth, n)]
        assert take_waiting(sub) == []

        t_end = time.monotonic() + 0.5                  # the n queued entries: none finds a message
        while time.monotonic() < t_end:
            executor.spin_once(timeout_sec=0.02)
        assert called == [-1.0]

        pub.publish(Float64MultiArray(data=[99.0]))     # and the executor still delivers
        _until(lambda: len(called) == 2, lambda: executor.spin_once(timeout_sec=0.02), 10.0, "a later message")
        assert called == [-1.0, 99.0]
        executor.shutdown()
        node.destroy_node()
    finally:
        if context.ok():
            rclpy.shutdown(context=context)


def test_take_waiting_received_gives_each_message_its_dds_reception(dds_env):
    """Messages published 20 ms apart and taken together 0.3 s later come with the times Fast DDS
    received them (perf_counter seconds): apart, after their publication, well before the take —
    not the take's one time (what a node that took a backlog in one go used as their arrival)."""
    from rclpy.context import Context
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray

    from ros2_node.taking import take_waiting_received

    context = Context()
    rclpy.init(context=context, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
    try:
        node = rclpy.create_node("taking_received_test", context=context)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        pub = node.create_publisher(Float64MultiArray, "taking_received_test", qos)
        sub = node.create_subscription(Float64MultiArray, "taking_received_test", lambda m: None, qos)
        _until(lambda: pub.get_subscription_count() > 0, lambda: time.sleep(0.02), 10.0, "the subscription")
        time.sleep(0.2)
        published = []
        for i in range(5):
            published.append(time.perf_counter())
            pub.publish(Float64MultiArray(data=[float(i)]))
            time.sleep(0.02)
        time.sleep(0.3)
        before_take = time.perf_counter()
        taken = take_waiting_received(sub)
        assert [m.data[0] for m, _ in taken] == [0.0, 1.0, 2.0, 3.0, 4.0]
        received = [t for _, t in taken]
        for p, r in zip(published, received):      # (the system clock mapped: a margin of 1 ms)
            assert p - 1e-3 <= r <= p + 0.1 and r < before_take - 0.2, (p, r, before_take)
        gaps = [b - a for a, b in zip(received, received[1:])]
        assert all(g > 0.005 for g in gaps), gaps  # the take's one time would give 0
        assert take_waiting_received(sub) == []
        node.destroy_node()
    finally:
        if context.ok():
            rclpy.shutdown(context=context)
