"""The twin node as a child process and a client node in this process (DDS test harness)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


class NodeProcess:
    """``flexmb node ...`` as a child process, its log in a file (``stderr``: where its stderr goes
    instead, e.g. ``subprocess.PIPE``)."""

    def __init__(self, args: list[str], env: dict, log_path: Path, stderr=subprocess.STDOUT):
        self.log_path = log_path
        self._log = open(log_path, "w")
        self.proc = subprocess.Popen([sys.executable, "-m", "flexmb.cli", "node", *args], env=env, cwd=ROOT,
                                     stdout=self._log, stderr=stderr)

    def log(self) -> str:
        self._log.flush()
        return self.log_path.read_text()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self, timeout: float = 20.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        self._log.close()
        return self.proc.returncode


def smooth_peak_force(model, span: float) -> float:
    """Peak |leg force| (N) of ``model`` run offline on its scene's own commands over [0, ``span``] s:
    the reference a command stream's peak is compared with."""
    import numpy as np

    from flexmb_io.twin import RunnerOptions, TwinRunner

    runner = TwinRunner(model, options=RunnerOptions(command_source="scene"))
    runner.start(warmup=False)
    peak = 0.0
    while runner.t < span - 1e-9:
        runner.step()
        peak = max(peak, float(np.abs(runner.sample(full=False).actuator_forces).max()))
    return peak


class TwinClient:
    """A client node: publishes commands to the twin, collects what it publishes."""

    def __init__(self, twin: str = "flexmb_twin", depth: int = 1000):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        from flexmb_io import topics as T
        from ros2_node.convert import message_class

        self.T = T
        self.context = Context()
        rclpy.init(context=self.context, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
        self.node = rclpy.create_node("flexmb_test_client", context=self.context)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        self.pub = {t.name: self.node.create_publisher(message_class(t.type), t.resolved(twin), qos)
                    for t in T.INPUTS}
        outputs = (T.JOINT_STATES, T.STATUS, T.PLATFORM_POSE, T.ACTUATOR_STATES, T.CLOCK, T.SHAPE, T.DIAGNOSTICS)
        self.received: dict[str, list] = {t.name: [] for t in outputs}
        self._subs = {t.name: self.node.create_subscription(message_class(t.type), t.resolved(twin),
                                                            lambda m, _n=t.name: self.received[_n].append(m), qos)
                      for t in outputs}
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, predicate, timeout: float, what: str, node: NodeProcess | None = None) -> None:
        t_end = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > t_end:
                log = node.log()[-3000:] if node is not None else ""
                raise AssertionError(f"timed out after {timeout} s waiting for {what}\nnode log:\n{log}")
            if node is not None and not node.alive():
                raise AssertionError(f"the node exited ({node.proc.returncode}) while waiting for {what}:\n{node.log()}")
            self.executor.spin_once(timeout_sec=0.02)

    def wait_for_twin(self, node: NodeProcess, timeout: float = 60.0) -> None:
        """Until the twin's first status arrived and it subscribes to every command topic."""
        self.spin_until(lambda: self.received[self.T.STATUS.name]
                        and all(p.get_subscription_count() > 0 for p in self.pub.values()),
                        timeout, "the twin node to come up", node)

    def unsubscribe(self, *topics) -> None:
        """Stop taking these outputs (what arrived stays in ``received``): a client that streams
        commands at 1 kHz in Python cannot also deserialize the twin's 1 kHz answers and keep its
        own ticks."""
        for t in topics:
            sub = self._subs.pop(t.name, None)
            if sub is not None:
                self.node.destroy_subscription(sub)

    def statuses(self):
        return self.received[self.T.STATUS.name]

    def stream_lengths(self, law, rate: float, span: float, on_tick=None) -> list[float]:
        """Send ``law(t)`` (lengths in scene order) as bare ``Float64MultiArray`` commands on this
        client's clock, at ``rate`` Hz for ``span`` s, as a controller samples its law at regular
        ticks (what jitters is delivery). The client's callbacks run meanwhile in a thread of their
        own, so that the sending loop keeps its ticks; ``on_tick()`` runs after each send. Returns
        each sample's lateness against its tick (s)."""
        import threading

        from flexmb_io import messages as M
        from ros2_node.convert import to_ros

        T = self.T
        to_ros(T.COMMANDS.type, M.float64_array(law(0.0)))       # warm: a first call loads compiled code
        running = True

        def spin():
            while running:
                self.executor.spin_once(timeout_sec=0.01)

        spinner = threading.Thread(target=spin, daemon=True)
        spinner.start()
        late, w0 = [], time.perf_counter()
        try:
            for k in range(int(span * rate)):
                time.sleep(max(0.0, w0 + k / rate - time.perf_counter()))
                late.append(time.perf_counter() - w0 - k / rate)
                self.publish(T.COMMANDS, to_ros(T.COMMANDS.type, M.float64_array(law(k / rate))))
                if on_tick is not None:
                    on_tick()
        finally:
            running = False
            spinner.join()
        return late

    def publish(self, topic, msg) -> None:
        self.pub[topic.name].publish(msg)

    def close(self) -> None:
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        if self.context.ok():
            rclpy.shutdown(context=self.context)
