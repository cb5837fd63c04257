"""flexmb_msgs on real DDS: a publisher in another process, a subscriber here, localhost only.

Also checks that TwinStatus and ActuatorState survive CDR serialization field by field.
Skipped when rclpy or flexmb_msgs is not installed (`make setup` installs both).
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time

import pytest

rclpy = pytest.importorskip("rclpy")
flexmb_msgs_msg = pytest.importorskip("flexmb_msgs.msg")

from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

ActuatorCommand = flexmb_msgs_msg.ActuatorCommand
ActuatorState = flexmb_msgs_msg.ActuatorState
TwinStatus = flexmb_msgs_msg.TwinStatus

pytestmark = pytest.mark.ros

TOPIC = "/flexmb_test/actuator_command"
NAMES = ["legs/leg1/actuator", "legs/leg2/actuator", "legs/leg3/actuator"]
N_WANTED = 5
DEADLINE_S = 20.0

# The child's message k carries header.stamp.sec = k, these names, and lengths/velocities
# computed by the same expressions in both processes, so float64 values compare exactly.
PUBLISHER = textwrap.dedent(
    """
    import sys, threading, time
    import rclpy
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from flexmb_msgs.msg import ActuatorCommand

    NAMES = {names!r}
    stop = threading.Event()
    # The parent closes our stdin to stop us; we also stop on our own after 30 s.
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()

    rclpy.init()
    node = rclpy.create_node("flexmb_test_publisher")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=50,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    pub = node.create_publisher(ActuatorCommand, {topic!r}, qos)
    print("publisher up", flush=True)
    k = 0
    t_end = time.monotonic() + 30.0
    while not stop.is_set() and time.monotonic() < t_end:
        msg = ActuatorCommand()
        msg.header.stamp.sec = k
        msg.header.frame_id = "world"
        msg.names = NAMES
        msg.lengths = [0.6 + 0.001 * k + i / 3.0 for i in range(len(NAMES))]
        msg.velocities = [-1.25e-3 * (i + 1) * k for i in range(len(NAMES))]
        pub.publish(msg)
        k += 1
        stop.wait(0.05)
    print(f"published {{k}}", flush=True)
    node.destroy_node()
    rclpy.shutdown()
    """
).format(names=NAMES, topic=TOPIC)


def expected_lengths(k: int) -> list[float]:
    return [0.6 + 0.001 * k + i / 3.0 for i in range(len(NAMES))]


def expected_velocities(k: int) -> list[float]:
    return [-1.25e-3 * (i + 1) * k for i in range(len(NAMES))]


@pytest.mark.timeout(60)
def test_actuator_command_crosses_processes(dds_env, tmp_path):
    script = tmp_path / "publisher.py"
    script.write_text(PUBLISHER)
    log_path = tmp_path / "publisher.log"
    domain = int(dds_env["ROS_DOMAIN_ID"])

    received: list = []
    with open(log_path, "w") as log:
        child = subprocess.Popen(
            [sys.executable, str(script)],
            stdin=subprocess.PIPE,
            stdout=log,
            stderr=subprocess.STDOUT,
            env=dds_env,
            cwd=tmp_path,
        )
        context = Context()
        try:
            rclpy.init(context=context, domain_id=domain)
            node = rclpy.create_node("flexmb_test_subscriber", context=context)
            qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST,
                depth=50,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.VOLATILE,
            )
            node.create_subscription(ActuatorCommand, TOPIC, received.append, qos)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)

            deadline = time.monotonic() + DEADLINE_S
            while len(received) < N_WANTED and time.monotonic() < deadline:
                if child.poll() is not None:
                    break
                executor.spin_once(timeout_sec=0.1)
            types = dict(node.get_topic_names_and_types())
            executor.shutdown()
            node.destroy_node()
        finally:
            if context.ok():
                rclpy.shutdown(context=context)
            if child.stdin is not None:
                child.stdin.close()  # asks the child to stop
            try:
                child_rc = child.wait(timeout=5)
            except subprocess.TimeoutExpired:
                child.kill()
                child_rc = child.wait(timeout=5)

    child_log = log_path.read_text()
    assert len(received) >= N_WANTED, (
        f"received {len(received)} ActuatorCommand message(s) on {TOPIC} within {DEADLINE_S} s, "
        f"expected {N_WANTED} (ROS_DOMAIN_ID={domain}); publisher rc={child_rc}, "
        f"output:\n{child_log}"
    )
    assert types.get(TOPIC) == ["flexmb_msgs/msg/ActuatorCommand"]

    seqs = [m.header.stamp.sec for m in received]
    # Reliable QoS: once matched, nothing is lost or reordered.
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    for m in received:
        k = m.header.stamp.sec
        assert m.header.frame_id == "world"
        assert list(m.names) == NAMES
        assert list(m.lengths) == expected_lengths(k)  # exact: same float64 computation
        assert list(m.velocities) == expected_velocities(k)
    assert child_rc == 0, f"publisher exited with {child_rc}:\n{child_log}"


def _set_header(msg, sec: int, nanosec: int, frame_id: str) -> None:
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    msg.header.frame_id = frame_id


def _assert_all_fields_listed(msg_type, values: dict) -> None:
    """Fails when a field is added to the .msg but not to this test."""
    assert set(values) | {"header"} == set(msg_type.get_fields_and_field_types())


def test_twin_status_round_trip():
    values = {
        "converged": True,
        "newton_iterations": 2**32 - 1,
        "residual": 3.0517578125e-5 / 3.0,
        "kinetic_energy": 1.0 / 3.0,
        "strain_energy": 2.5e-300,
        "total_energy": -12345.678901234567,
        "step_wall_time": 7.5e-4,
        "steps": 2**64 - 1,
        "deadline_misses": 2**40 + 3,
        "unconverged_steps": 17,
        "real_time_factor": 1.0000000000000002,
        "sim_time": 123.456,
        "substeps": 4,
        "message": "step 17: residual 1e-3 > tol (Δt halved)",
        "command_latency": 2.5e-4, "command_age": 1.5e-3,
        "rejected_commands": 2**33 + 1,
    }
    _assert_all_fields_listed(TwinStatus, values | {"command_stamp": None})
    msg = TwinStatus(**values)
    _set_header(msg, 2**31 - 1, 999_999_999, "world")
    msg.command_stamp.sec, msg.command_stamp.nanosec = 17, 1_000

    back = deserialize_message(serialize_message(msg), TwinStatus)

    assert back.header.stamp.sec == 2**31 - 1
    assert back.header.stamp.nanosec == 999_999_999
    assert back.header.frame_id == "world"
    assert (back.command_stamp.sec, back.command_stamp.nanosec) == (17, 1_000)
    for name, value in values.items():
        got = getattr(back, name)
        assert got == value and type(got) is type(value), f"{name}: sent {value!r}, got {got!r}"
    assert back == msg


def test_actuator_state_round_trip():
    n = len(NAMES)
    values = {
        "names": NAMES,
        "lengths": [0.75 + i / 7.0 for i in range(n)],
        "velocities": [-0.1 * i for i in range(n)],
        "commanded_lengths": [0.8 + i / 11.0 for i in range(n)],
        "axial_forces": [-1520.25, 0.0, 3.0e4],
    }
    _assert_all_fields_listed(ActuatorState, values)
    msg = ActuatorState(**values)
    _set_header(msg, 5, 250_000_000, "world")

    back = deserialize_message(serialize_message(msg), ActuatorState)

    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (5, 250_000_000)
    assert back.header.frame_id == "world"
    for name, value in values.items():
        assert list(getattr(back, name)) == value, name
    assert back == msg
