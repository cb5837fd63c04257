"""One message path: the bytes the node publishes are the bytes it records, and the offline form
(``flexmb_io.messages`` + ``flexmb_io.wire``, what ``flexmb run --mcap`` writes, no rclpy) gives the
same bytes for the same sample; rclpy reads every one of them as its own message type."""

from __future__ import annotations

from collections import defaultdict

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("flexmb_msgs.msg")

from dds_harness import ROOT, NodeProcess, TwinClient  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402
from flexmb_io import messages as M  # noqa: E402
from flexmb_io import topics as T  # noqa: E402
from flexmb_io import wire  # noqa: E402
from flexmb_io.bag.lockstep import input_kinds, run_lockstep  # noqa: E402
from flexmb_io.bag.reader import BagReader, obj_to_dict  # noqa: E402
from flexmb_io.twin import TwinRunner  # noqa: E402

SCENE = "scenes/stewart_platform_bars.yaml"
STEPS = 30
# outputs fixed by the sample alone (the status carries wall-clock timing, compared by decoding)
DETERMINISTIC = (T.JOINT_STATES, T.ACTUATOR_STATES, T.SHAPE, T.CLOCK, T.TF)


def _stamp_ns(type_name: str, data: bytes) -> int:
    m = wire.deserialize(type_name, data)
    st = m.clock if type_name == T.CLOCK.type else (m.transforms[0].header.stamp if type_name == T.TF.type
                                                   else m.markers[0].header.stamp if type_name == T.SHAPE.type
                                                   else m.header.stamp)
    return st.sec * 1_000_000_000 + st.nanosec


@pytest.mark.timeout(240)
def test_published_recorded_and_offline_bytes_are_equal(tmp_path, dds_env):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message

    from ros2_node.convert import message_class, to_dict

    bag = tmp_path / "bag"
    node = NodeProcess([SCENE, "--mode", "lockstep", "--publish-rate", "1000", "--shape-rate", "1000",
                        "--mcap", str(bag)], dds_env, tmp_path / "node.log")
    program = Simulator(compile_scene(load_scene(str(ROOT / SCENE))))
    client = TwinClient()
    raw: dict[str, list[bytes]] = defaultdict(list)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    for topic in (*DETERMINISTIC, T.STATUS, T.PLATFORM_POSE):
        name = topic.resolved() if topic is not T.PLATFORM_POSE else T.pose_topic("platform", 0).resolved()
        client.node.create_subscription(message_class(topic.type), name,
                                        lambda m, _t=topic: raw[_t.name].append(m), qos, raw=True)
    try:
        client.wait_for_twin(node)
        for k in range(1, STEPS + 1):
            before = max((int(s.steps) for s in client.statuses()), default=0)
            # the command as bytes too: the node takes them as any rclpy publisher's
            client.publish(T.ACTUATOR_COMMANDS, wire.serialize(T.ACTUATOR_COMMANDS.type, M.actuator_command(
                k * 1e-3, program.model.actuators.names, program.command_lengths(k * 1e-3))))
            client.spin_until(lambda: max((int(s.steps) for s in client.statuses()), default=0) > before, 30,
                              f"step {k}", node)
        client.spin_until(lambda: all(raw[t.name] for t in DETERMINISTIC), 10, "one message per output", node)
    finally:
        client.close()
        assert node.stop() == 130, node.log()

    # what the node recorded, by topic and stamp
    reader = BagReader(bag)
    recorded: dict[tuple[str, int], set[bytes]] = defaultdict(set)
    commands = []
    kinds = input_kinds("flexmb_twin")
    for m in reader.messages():
        recorded[(m.topic, _stamp_ns(m.type, m.data) if m.topic in {t.resolved() for t in DETERMINISTIC}
                  else m.log_time_ns)].add(m.data)
        if m.topic in kinds:
            commands.append((m.log_time_ns, m.topic, kinds[m.topic], obj_to_dict(m.decode()), m.arrival))
    assert len(commands) == STEPS

    # published == recorded, byte for byte (DDS pads a serialized sample to a multiple of 4 bytes)
    for topic in DETERMINISTIC:
        assert raw[topic.name], topic.name
        for data in raw[topic.name]:
            same = [r for r in recorded[(topic.resolved(), _stamp_ns(topic.type, data))]
                    if data[:len(r)] == r and set(data[len(r):]) <= {0} and len(data) - len(r) < 4]
            assert same, topic.name
    # rclpy reads the wire bytes as its own messages (status included), with the same values
    for topic in (*DETERMINISTIC, T.STATUS, T.PLATFORM_POSE):
        for data in raw[topic.name][:3]:
            ours = wire.plain(wire.deserialize(topic.type, data))
            theirs = to_dict(deserialize_message(data, message_class(topic.type)))
            assert _close(theirs, ours), topic.name

    # the offline form: the same commands through an offline runner, each output built and serialized
    model = compile_scene(load_scene(str(ROOT / SCENE)))
    runner = TwinRunner(model)
    runner.start()
    offline: dict[tuple[str, int], bytes] = {}

    def at(t_ns: int) -> bool:
        s = runner.sample()
        built = {T.JOINT_STATES: M.joint_state(s), T.ACTUATOR_STATES: M.actuator_state(s), T.CLOCK: M.clock(s.t),
                 T.SHAPE: M.shape(s, runner.member_kinds, runner.shells), T.TF: M.tf(s)}
        for topic, msg in built.items():
            offline[(topic.resolved(), t_ns)] = wire.serialize(topic.type, msg)
        return True

    last = max(k[1] for k in recorded if k[0] == T.JOINT_STATES.resolved())
    run_lockstep(runner, commands, last_ns=last, until=None, at=at)
    compared: dict[str, int] = defaultdict(int)
    for (topic, t_ns), datas in recorded.items():
        if (topic, t_ns) in offline:
            assert offline[(topic, t_ns)] in datas, (topic, t_ns)
            compared[topic] += 1
    assert compared[T.JOINT_STATES.resolved()] >= STEPS, dict(compared)      # every step answers its command
    assert all(compared[t.resolved()] >= 1 for t in DETERMINISTIC), dict(compared)


def _close(a, b) -> bool:
    """Equal values; float32 fields compare at float32 (rclpy's to_dict widens them)."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if isinstance(a, float):
        return a == b or abs(a - b) <= 1e-7 * max(1.0, abs(b))
    return a == b
