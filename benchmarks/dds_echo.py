"""A bare rclpy echo with the twin node's interface: the DDS baseline of ``node_latency.py``.

It subscribes to ``/flexmb_twin/actuator_commands`` (``flexmb_msgs/ActuatorCommand``) and answers
each command at once, in the subscription callback, with a ``flexmb_msgs/TwinStatus`` on
``/flexmb_twin/status`` whose ``command_stamp`` echoes the command's stamp — the message the twin
answers with — and publishes ``/clock`` (wall time since start) at 100 Hz so that ``flexmb play``
can stamp its commands. Same QoS as the node (reliable, volatile, keep last 10), same executor
(rclpy's ``EventsExecutor``). No solver, no state: what is left of the twin's latency is DDS and
rclpy.

    .venv/bin/python benchmarks/dds_echo.py --seconds 30
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=30.0, help="wall seconds to run")
    ap.add_argument("--json", help="write the echo's CPU time and the commands it answered here on exit")
    args = ap.parse_args()
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    import rclpy
    from flexmb_msgs.msg import ActuatorCommand, TwinStatus
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("flexmb_twin", context=ctx)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    status_pub = node.create_publisher(TwinStatus, "/flexmb_twin/status", qos)
    clock_pub = node.create_publisher(Clock, "/clock", qos)
    status, clock = TwinStatus(), Clock()
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    answered = [0]

    def write_cpu() -> None:
        if args.json:
            wall = time.perf_counter() - t0
            cpu = time.process_time() - cpu0
            with open(args.json, "w") as f:
                json.dump({"cpu_s": cpu, "wall_s": wall, "core_fraction": cpu / wall, "answered": answered[0]}, f)

    def sim_time() -> float:
        return time.perf_counter() - t0

    def stamp(msg_time, t: float) -> None:
        msg_time.sec = int(t)
        msg_time.nanosec = int(round((t - int(t)) * 1e9)) % 1_000_000_000

    def on_command(msg) -> None:
        t = sim_time()
        status.command_stamp = msg.header.stamp
        status.sim_time = t
        stamp(status.header.stamp, t)
        status.converged = True
        status_pub.publish(status)
        answered[0] += 1

    def on_timer() -> None:
        stamp(clock.clock, sim_time())
        clock_pub.publish(clock)

    node.create_subscription(ActuatorCommand, "/flexmb_twin/actuator_commands", on_command, qos)
    node.create_timer(0.01, on_timer)
    ex = EventsExecutor(context=ctx)
    ex.add_node(node)
    end = t0 + args.seconds
    next_write = t0 + 1.0
    try:
        while time.perf_counter() < end and ctx.ok():
            ex.spin_once(timeout_sec=0.05)
            if time.perf_counter() >= next_write:       # the caller may kill us: written every second
                next_write += 1.0
                write_cpu()
    except KeyboardInterrupt:
        pass
    finally:
        write_cpu()
        node.destroy_node()
        if ctx.ok():
            rclpy.shutdown(context=ctx)
    return 0


if __name__ == "__main__":
    sys.exit(main())
