"""The twin node in a ROS 2 system (issue 14), each node a separate process on real DDS:

- ``sensor_msgs/JointState`` commands on ``~/joint_commands`` (the ``topic_based_ros2_control``
  convention: names in any order) drive a lockstep twin exactly as an offline run of the same
  lengths; an unknown name is rejected naming the topic and the name; the recording replays
  bit-identically;
- two twins in two namespaces side by side: each answers only its own commands, topics and the
  recording follow the namespace, the platform frames carry the namespace as prefix;
- the managed node: configure / activate / deactivate / cleanup / shutdown through
  ``lifecycle_msgs/srv/ChangeState``, and the ``~/pause``, ``~/step``, ``~/resume``, ``~/reset``
  services; ``/clock`` at ``clock_rate`` apart from ``publish_rate``;
- a best-effort command publisher drives the twin; a ``qos_overrides`` parameter makes one command
  subscription reliable, which a best-effort publisher then cannot match (ROS 2's QoS rule).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("flexmb_msgs.msg")
pytest.importorskip("lifecycle_msgs.srv")

from dds_harness import ROOT, NodeProcess  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_core.simulator import Simulator  # noqa: E402
from flexmb_io import messages as M  # noqa: E402
from flexmb_io.bag.reader import BagReader  # noqa: E402
from ros2_node.convert import message_class, to_ros  # noqa: E402
from flexmb_io.twin import TwinRunner  # noqa: E402

pytestmark = pytest.mark.ros

SCENE = "scenes/stewart_platform_bars.yaml"
F64, JS, STATUS = "std_msgs/msg/Float64MultiArray", "sensor_msgs/msg/JointState", "flexmb_msgs/msg/TwinStatus"


@pytest.fixture(scope="module")
def stewart():
    model = compile_scene(load_scene(str(ROOT / SCENE)))
    return model, Simulator(model)          # the simulator only for the scene's command law L(t)


class Client:
    """A client node of any topic and service, collecting what arrives per topic."""

    def __init__(self):
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self.context = Context()
        rclpy.init(context=self.context, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
        self.node = rclpy.create_node("flexmb_ecosystem_client", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: dict[str, list] = {}
        self.pubs: dict[str, object] = {}

    @staticmethod
    def qos(best_effort: bool = False, depth: int = 1000):
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, durability=DurabilityPolicy.VOLATILE,
                          reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE)

    def listen(self, type_name: str, topic: str) -> list:
        self.received[topic] = []
        self.node.create_subscription(message_class(type_name), topic, self.received[topic].append, self.qos())
        return self.received[topic]

    def publisher(self, type_name: str, topic: str, best_effort: bool = False, key: str | None = None):
        pub = self.node.create_publisher(message_class(type_name), topic, self.qos(best_effort))
        self.pubs[key or topic] = pub
        return pub

    def spin_until(self, predicate, timeout: float, what: str, *nodes: NodeProcess) -> None:
        t_end = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > t_end:
                logs = "\n".join(n.log()[-2000:] for n in nodes)
                raise AssertionError(f"timed out after {timeout} s waiting for {what}\nnode logs:\n{logs}")
            for n in nodes:
                if not n.alive():
                    raise AssertionError(f"a node exited ({n.proc.returncode}) while waiting for {what}:\n{n.log()}")
            self.executor.spin_once(timeout_sec=0.02)

    def spin_for(self, seconds: float) -> None:
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            self.executor.spin_once(timeout_sec=0.02)

    def call(self, srv_type, name: str, request, timeout: float, *nodes: NodeProcess, resend_after: float = 0.0):
        """The answer of a service. ``resend_after`` > 0, for a query only (asking twice changes
        nothing): ask again when no answer came within that many seconds. A server that has not yet
        discovered a new client's response reader drops its answer ("failed to send response
        (timeout)", seen once in ``make test`` on a loaded machine); ``service_is_ready`` only
        covers the request's way."""
        cli = self.node.create_client(srv_type, name)
        self.spin_until(cli.service_is_ready, timeout, f"service {name}", *nodes)
        t_end = time.monotonic() + timeout
        while True:
            future = cli.call_async(request)
            wait = min(resend_after, t_end - time.monotonic()) if resend_after > 0 else timeout
            try:
                self.spin_until(future.done, max(wait, 0.0), f"the answer of {name}", *nodes)
                break
            except AssertionError as exc:     # a timeout is resent; a node that exited is not
                if resend_after <= 0 or time.monotonic() >= t_end or not str(exc).startswith("timed out"):
                    raise
        self.node.destroy_client(cli)
        return future.result()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        if self.context.ok():
            rclpy.shutdown(context=self.context)


def _steps(statuses) -> int:
    return max((int(s.steps) for s in statuses), default=0)


def _send(client, pub, msg, statuses, *nodes, timeout=30.0) -> None:
    """Publish and wait for the lockstep twin's status of the step it caused."""
    before = _steps(statuses)
    pub.publish(msg)
    client.spin_until(lambda: _steps(statuses) > before, timeout, "the status answering a command", *nodes)


def _stamp_ns(m) -> int:
    return m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec


def _joint_state(names, lengths, order):
    return to_ros(JS, {"header": M.header(0.0), "name": [names[i] for i in order],
                       "position": [float(lengths[i]) for i in order], "velocity": [], "effort": []})


@pytest.mark.timeout(240)
def test_joint_state_commands_drive_the_twin_like_float64_commands(tmp_path, dds_env, stewart):
    model, program = stewart
    names = list(model.actuators.names)
    bag = tmp_path / "bag"
    node = NodeProcess([SCENE, "--mode", "lockstep", "--publish-rate", "1000", "--mcap", str(bag)], dds_env,
                       tmp_path / "node.log")
    client = Client()
    statuses = client.listen(STATUS, "/flexmb_twin/status")
    joints = client.listen(JS, "/joint_states")
    pub = client.publisher(JS, "/flexmb_twin/joint_commands")
    offline = TwinRunner(model)
    offline.start()
    expected = {}
    steps = 120
    try:
        client.spin_until(lambda: statuses and pub.get_subscription_count() > 0, 90, "the twin", node)
        for k in range(steps):
            lengths = program.command_lengths(offline.t + offline.dt)
            order = np.random.default_rng(k).permutation(len(names))       # any order of the names
            _send(client, pub, _joint_state(names, lengths, order), statuses, node)
            assert offline.command_array("/flexmb_twin/commands", lengths) is None     # the same, as an array
            offline.step()
            s = offline.sample()
            expected[round(s.t * 1e9)] = (s.actuator_lengths.copy(), s.actuator_forces.copy())
        client.spin_until(lambda: any(_stamp_ns(m) == round(offline.t * 1e9) for m in joints), 10,
                          "the last joint states", node)
        bad = _joint_state(["leg1", "no_such_leg"], [1.0, 1.0], [0, 1])
        _send(client, pub, bad, statuses, node)          # rejected, and the lockstep twin still steps once
    finally:
        client.close()
        assert node.stop() == 130, node.log()
    log = node.log_path.read_text()     # complete once the node stopped (its log is written apart)
    worst = 0.0
    compared = 0
    for m in joints:
        if _stamp_ns(m) in expected:
            lengths, forces = expected[_stamp_ns(m)]
            assert list(m.name[:6]) == names
            worst = max(worst, np.abs(np.array(m.position[:6]) - lengths).max(),
                        np.abs(np.array(m.effort[:6]) - forces).max() / max(1.0, np.abs(forces).max()))
            compared += 1
    assert compared >= steps and worst <= 1e-12, f"{compared} states, worst deviation {worst:.3e}"
    last = statuses[-1]
    assert last.rejected_commands == 1 and last.steps == steps + 1
    assert "/flexmb_twin/joint_commands: rejected (unknown_name): unknown actuator names [no_such_leg]" in log
    # recorded like the other command topics, and replayed offline to the last bit
    assert BagReader(bag).counts()["/flexmb_twin/joint_commands"] == steps + 1
    p = subprocess.run([sys.executable, "-m", "flexmb.cli", "replay", str(bag)], cwd=ROOT, env=dds_env,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0 and "bit-identical" in p.stdout, p.stdout + p.stderr


@pytest.mark.timeout(300)
def test_two_namespaced_twins_run_side_by_side_without_crosstalk(tmp_path, dds_env, stewart):
    model, program = stewart
    bag = tmp_path / "robot1_bag"
    robot1 = NodeProcess([SCENE, "--mode", "lockstep", "--mcap", str(bag), "--ros-args", "-r", "__ns:=/robot1"],
                         dds_env, tmp_path / "robot1.log")
    robot2 = NodeProcess([SCENE, "--mode", "lockstep", "--ros-args", "-r", "__ns:=/robot2", "-p",
                          "publish_clock:=false", "-p", "world_frame:=robot2_world"], dds_env, tmp_path / "robot2.log")
    client = Client()
    st = {r: client.listen(STATUS, f"/{r}/flexmb_twin/status") for r in ("robot1", "robot2")}
    js = {r: client.listen(JS, f"/{r}/joint_states") for r in ("robot1", "robot2")}
    poses = {r: client.listen("geometry_msgs/msg/PoseStamped", f"/{r}/flexmb_twin/platform_pose")
             for r in ("robot1", "robot2")}
    pub = {r: client.publisher(F64, f"/{r}/flexmb_twin/commands") for r in ("robot1", "robot2")}
    # robot1 follows the scene's law, robot2 holds its legs 10 mm longer
    offline = {r: TwinRunner(model) for r in ("robot1", "robot2")}
    for r in offline.values():
        r.start()
    rest = program.command_lengths(0.0)
    law = {"robot1": lambda t: program.command_lengths(t), "robot2": lambda t: rest + 0.01}
    count = {"robot1": 40, "robot2": 25}
    try:
        client.spin_until(lambda: all(st.values()) and all(p.get_subscription_count() > 0 for p in pub.values()),
                          120, "both twins", robot1, robot2)
        for k in range(max(count.values())):
            for r in ("robot1", "robot2"):
                if k < count[r]:
                    lengths = law[r](offline[r].t + offline[r].dt)
                    _send(client, pub[r], to_ros(F64, M.float64_array(lengths)), st[r], robot1, robot2)
                    offline[r].command_array("/x", lengths)
                    offline[r].step()
        for r in ("robot1", "robot2"):
            client.spin_until(lambda r=r: any(_stamp_ns(m) == round(offline[r].t * 1e9) for m in js[r]), 10,
                              f"the last joint states of {r}", robot1, robot2)
        topics = dict(client.node.get_topic_names_and_types())
        clock_publishers = client.node.count_publishers("/clock")
    finally:
        client.close()
        assert robot1.stop() == 130, robot1.log()
        assert robot2.stop() == 130, robot2.log()
    for r in ("robot1", "robot2"):
        assert _steps(st[r]) == count[r], f"{r}: {_steps(st[r])} steps for {count[r]} commands of its own"
        last = max(js[r], key=_stamp_ns)
        s = offline[r].sample()
        assert _stamp_ns(last) == round(s.t * 1e9)
        assert np.abs(np.array(last.position[:6]) - s.actuator_lengths).max() <= 1e-12
    # the two really differ (robot2 does not move with robot1's law)
    assert np.abs(np.array(max(js["robot1"], key=_stamp_ns).position[:6])
                  - np.array(max(js["robot2"], key=_stamp_ns).position[:6])).max() > 1e-3
    # nothing at the root namespace; one /clock (robot2 does not publish it)
    assert "/joint_states" not in topics and not any(t.startswith("/flexmb_twin/") for t in topics)
    assert "/robot1/flexmb_twin/joint_commands" in topics and "/robot2/flexmb_twin/shape" in topics
    assert clock_publishers == 1
    assert {m.header.frame_id for m in poses["robot1"]} == {"world"}
    assert {m.header.frame_id for m in poses["robot2"]} == {"robot2_world"}
    # robot1's recording: namespaced names, prefixed platform frame, the namespace in its settings
    reader = BagReader(bag)
    counts = reader.counts()
    assert counts["/robot1/flexmb_twin/commands"] == count["robot1"] and counts["/robot1/joint_states"] >= 40
    assert reader.setting("node_namespace") == "/robot1" and reader.setting("node_name") == "flexmb_twin"
    tf = [m.decode() for m in reader.messages({"/tf"})]
    assert tf and {t.child_frame_id for m in tf for t in m.transforms} == {"robot1/platform"}
    assert {t.header.frame_id for m in tf for t in m.transforms} == {"world"}
    # and it replays offline: the namespace and the frame prefix come from the bag's settings
    from flexmb_io.bag.replay import replay

    rep = replay(bag)
    assert rep.ok and rep.samples_compared > 0 and rep.commands_applied == count["robot1"], rep.format()
    assert any(f.topic == "/tf" for f in rep.fields), rep.format()


def _lifecycle(client, name: str, transition: str, *nodes):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    req = ChangeState.Request()
    req.transition.id = getattr(Transition, f"TRANSITION_{transition.upper()}")
    return client.call(ChangeState, f"{name}/change_state", req, 120, *nodes).success


def _state(client, name: str, *nodes) -> str:
    from lifecycle_msgs.srv import GetState

    return client.call(GetState, f"{name}/get_state", GetState.Request(), 30, *nodes,
                       resend_after=5.0).current_state.label


def _sim_time(m) -> float:
    return m.clock.sec + 1e-9 * m.clock.nanosec


@pytest.mark.timeout(300)
def test_lifecycle_transitions_and_services(tmp_path, dds_env):
    from flexmb_msgs.srv import Step
    from std_srvs.srv import Trigger

    name = "/flexmb_twin"
    node = NodeProcess([SCENE, "--mode", "realtime", "--lifecycle", "--publish-rate", "200", "--clock-rate", "50"],
                       dds_env, tmp_path / "node.log")
    client = Client()
    statuses = client.listen(STATUS, f"{name}/status")
    clocks = client.listen("rosgraph_msgs/msg/Clock", "/clock")
    joints = client.listen(JS, "/joint_states")
    cmd = client.publisher(F64, f"{name}/commands")

    def newest() -> float:
        """The twin's time in the status received last (one publisher: DDS keeps its order)."""
        return statuses[-1].sim_time if statuses else -1.0

    def quiet(seconds=0.4) -> float:
        """The newest sim time once nothing new is in flight (a held twin publishes nothing)."""
        client.spin_for(seconds)
        return newest()

    def trigger(what):
        return client.call(Trigger, f"{name}/{what}", Trigger.Request(), 60, node)

    try:
        assert _state(client, name, node) == "unconfigured"
        refused = trigger("pause")
        assert not refused.success and "unconfigured" in refused.message
        assert _lifecycle(client, name, "configure", node) and _state(client, name, node) == "inactive"
        assert not statuses                                 # configured, not stepping: nothing published
        assert _lifecycle(client, name, "activate", node) and _state(client, name, node) == "active"
        client.spin_until(lambda: newest() > 0.3, 30, "the active twin to step", node)

        # /clock at clock_rate (50 Hz of simulated time), joint states at publish_rate (200 Hz)
        ct = np.array([_sim_time(m) for m in clocks])
        jt = np.array(sorted({_stamp_ns(m) for m in joints})) * 1e-9
        assert len(ct) >= 10 and np.allclose(np.diff(ct), 0.02, atol=1e-9)
        # joint states on the 5 ms grid; a loaded machine may coalesce one (the node publishes the
        # newest state when its publisher falls behind), so gaps are whole multiples of 5 ms
        dj = np.diff(jt)
        assert np.allclose(dj / 0.005, np.round(dj / 0.005), atol=1e-6) and np.median(dj) == pytest.approx(0.005)

        # pause: time stops; step N: exactly N Δt, answered with the state; resume: time runs again
        assert trigger("pause").success
        t_paused = quiet()
        assert quiet() == t_paused
        r = client.call(Step, f"{name}/step", Step.Request(steps=100), 60, node)
        assert r.success and r.steps_done == 100 and abs(r.sim_time - (t_paused + 0.1)) < 1e-9, r
        client.spin_until(lambda: abs(newest() - r.sim_time) < 1e-12, 10, "the status after ~/step", node)
        assert quiet() == r.sim_time
        assert trigger("resume").success
        client.spin_until(lambda: newest() > r.sim_time + 0.2, 30, "the resumed twin", node)
        running = client.call(Step, f"{name}/step", Step.Request(steps=5), 60, node)
        assert not running.success and "~/pause" in running.message

        # reset: back to t = 0 (the twin runs on from there)
        assert trigger("reset").success
        n_before = len(statuses)
        client.spin_until(lambda: any(s.sim_time < 0.1 for s in statuses[n_before:]), 30, "the reset twin", node)

        # deactivate: held with its state, commands ignored; activate: on from the same time
        assert _lifecycle(client, name, "deactivate", node) and _state(client, name, node) == "inactive"
        t_held = quiet()
        cmd.publish(to_ros(F64, M.float64_array([1.0] * 6)))
        assert quiet(0.6) == t_held
        assert _lifecycle(client, name, "activate", node)
        n_before = len(statuses)
        client.spin_until(lambda: len(statuses) > n_before + 5, 30, "the re-activated twin", node)
        assert min(s.sim_time for s in statuses[n_before:]) >= t_held

        # cleanup drops the topics; shutdown ends the node (exit 0: not a signal)
        assert _lifecycle(client, name, "deactivate", node) and _lifecycle(client, name, "cleanup", node)
        assert _state(client, name, node) == "unconfigured"
        client.spin_until(lambda: client.node.count_publishers(f"{name}/status") == 0, 10, "the topics gone", node)
        assert _lifecycle(client, name, "unconfigured_shutdown", node)
        node.proc.wait(timeout=30)
        log = node.log()
    finally:
        client.close()
        rc = node.stop()
    assert rc == 0, log
    assert "/flexmb_twin/commands: ignored: the node is inactive" in log


@pytest.mark.timeout(240)
def test_best_effort_publisher_drives_the_twin_and_qos_overrides_apply(tmp_path, dds_env, stewart):
    model, program = stewart
    node = NodeProcess([SCENE, "--mode", "lockstep", "--ros-args", "-p",
                        "qos_overrides./flexmb_twin/joint_commands.subscription.reliability:=reliable"],
                       dds_env, tmp_path / "node.log")
    client = Client()
    statuses = client.listen(STATUS, "/flexmb_twin/status")
    best_effort = client.publisher(F64, "/flexmb_twin/commands", best_effort=True)
    js_best_effort = client.publisher(JS, "/flexmb_twin/joint_commands", best_effort=True, key="be")
    js_reliable = client.publisher(JS, "/flexmb_twin/joint_commands", key="rel")
    try:
        client.spin_until(lambda: statuses and best_effort.get_subscription_count() > 0
                          and js_reliable.get_subscription_count() > 0, 90, "the twin", node)
        for k in range(1, 21):
            _send(client, best_effort, to_ros(F64, M.float64_array(program.command_lengths(k * 1e-3))), statuses,
                  node)
        assert _steps(statuses) == 20
        # the overridden (reliable) subscription cannot hear a best-effort publisher
        client.spin_for(1.0)
        matched = js_best_effort.get_subscription_count()
    finally:
        client.close()
        assert node.stop() == 130, node.log()
    assert matched == 0
