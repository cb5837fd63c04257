"""``flexmb node SCENE``: the twin as a ROS 2 node (rclpy, real DDS).

Commands in (``~/commands``, ``~/actuator_commands``, ``~/joint_trajectory``), the flexible
mechanism out (``/joint_states``, ``~/actuator_states``, ``~/platform_pose``, ``~/shape``,
``~/status``, ``/clock``); names and types in :mod:`ros2_node.topics`. The solver lives in a
:class:`~ros2_node.twin.TwinRunner`; this module only moves messages and keeps time.

Timing. ``realtime``: step k must finish by ``t_start + k Δt`` on the wall clock; the loop sleeps
in the executor until then, so commands are taken as they arrive, and every late step counts as
a deadline miss. ``lockstep``: one step per received command message, deterministic, so a lockstep
run equals an offline replay of its commands (:mod:`ros2_node.bag`). Warm-up (numba compile or
cache load) happens before the first step, outside the timed loop.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import math
import signal
import time
from pathlib import Path

import numpy as np

from flexmb_core.errors import FlexmbError
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene

from . import messages as M
from . import topics as T
from .convert import message_class, to_dict
from .live_messages import LiveMessages
from .params import SPECS, NodeParams
from .twin import RunnerOptions, TwinRunner, apply_message

# s before a realtime deadline at which the loop stops sleeping and polls
_WAKE_MARGIN = 4.0e-4
# s of wall time between two status messages of an idle lockstep twin
_HEARTBEAT = 0.2

# topic kind → (topic, what apply_message calls it)
_INPUTS = ((T.COMMANDS, "commands"), (T.ACTUATOR_COMMANDS, "actuator_commands"), (T.TRAJECTORY, "joint_trajectory"))


class _Samples:
    """The newest ``capacity`` values of a per-step quantity, in a buffer allocated once (a node runs
    for hours: a growing list would allocate at every step), and the count and sum of all of them."""

    def __init__(self, capacity: int = 1 << 19):
        self._buf = np.empty(capacity)
        self.count = 0
        self.total = 0.0

    def add(self, x: float) -> None:
        self._buf[self.count % self._buf.size] = x
        self.count += 1
        self.total += x

    def percentiles(self, qs=(50, 99), sign: float = 1.0) -> dict:
        """Percentiles of ``sign`` × the values in the window, its max, and how many values it holds."""
        a = sign * self._buf[:min(self.count, self._buf.size)]
        if not a.size:
            return {f"p{q}": 0.0 for q in qs} | {"max": 0.0, "count": 0}
        return {f"p{q}": float(np.percentile(a, q)) for q in qs} | {"max": float(a.max()), "count": int(a.size)}


class TwinNode:
    """The twin node. Build it, then :meth:`spin` until the duration ends or ROS shuts down.

    Parameters
    ----------
    values : parameter values from the command line (the ``--ros-args -p`` overrides win)
    context : rclpy context (initialised by the caller)
    node_name : ROS node name (private topics live under it)
    """

    def __init__(self, values: dict, *, context, node_name: str = T.DEFAULT_NODE_NAME):
        import rclpy
        from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        self._rclpy = rclpy
        self.context = context
        self.node = rclpy.create_node(node_name, context=context)
        self.log = self.node.get_logger()
        self.node_name = self.node.get_name()

        # -- parameters: declared with descriptors; --ros-args -p overrides win over flags ----------
        effective = {}
        for spec in SPECS:
            desc = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
            if spec.choices:
                desc.additional_constraints = f"one of {list(spec.choices)}"
            if spec.low is not None and isinstance(spec.default, float):
                desc.floating_point_range = [FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high))]
            elif spec.low is not None and isinstance(spec.default, int) and not isinstance(spec.default, bool):
                desc.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
            value = values.get(spec.name, spec.default)
            if isinstance(spec.default, float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            effective[spec.name] = self.node.declare_parameter(spec.name, value, desc).value
        self.p = NodeParams.from_values(effective)
        if self.p.mode == "lockstep" and self.p.command_source == "scene":
            raise FlexmbError("parameter 'mode': lockstep steps once per received command, so it needs "
                              "command_source 'external', got 'scene'")
        self.node.add_on_set_parameters_callback(self._on_set_parameters)

        # -- the twin: compile, warm up, initial state (outside any timed loop) ---------------------
        overrides = {"dt": self.p.dt or None, "integrator": self.p.integrator or None}
        self.scene_path = self.p.scene
        scene = load_scene(self.p.scene, overrides)
        self.model = compile_scene(scene)
        options = RunnerOptions(command_source=self.p.command_source, command_timeout=self.p.command_timeout,
                                timeout_behaviour=self.p.command_timeout_behaviour, ramp_time=self.p.ramp_time,
                                stale_after=self.p.stale_after, max_lead=self.p.max_lead)
        self.runner = TwinRunner(self.model, options=options)
        t0 = time.perf_counter()
        self.runner.start()
        self.warmup_s = time.perf_counter() - t0
        self.dt = self.runner.dt

        # -- publishers / subscriptions ------------------------------------------------------------
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.p.qos_depth,
                         reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
        n = self.node_name
        self._pub = {}
        outputs = [T.JOINT_STATES, T.ACTUATOR_STATES, T.SHAPE, T.STATUS]
        self._pose_topics = [T.pose_topic(p.name, i) for i, p in enumerate(self.runner.sample().poses)]
        outputs += self._pose_topics
        if self.p.publish_clock:
            outputs.append(T.CLOCK)
        try:
            message_class(T.TF.type)
            if self._pose_topics:
                outputs.append(T.TF)
        except ModuleNotFoundError:
            pass                    # no tf2_msgs here (PyPI): /tf goes to recordings only
        for topic in outputs:
            self._pub[topic.name] = self.node.create_publisher(message_class(topic.type), topic.resolved(n), qos)
        self.live = LiveMessages(self.runner.sample())
        self._subs = []
        if self.runner.schedule is not None:
            for topic, kind in _INPUTS:
                cb = (lambda msg, _t=topic, _k=kind: self._on_command(_t, _k, msg))
                self._subs.append(self.node.create_subscription(message_class(topic.type), topic.resolved(n), cb, qos))

        # -- executor: the C++ events executor keeps 1 kHz; the default one as fallback -------------
        try:
            from rclpy.experimental import EventsExecutor
            self.executor = EventsExecutor(context=context)
        except Exception:          # pragma: no cover - older rclpy
            from rclpy.executors import SingleThreadedExecutor
            self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)

        # -- recording and viewing ------------------------------------------------------------------
        self.recorder = None
        if self.p.record:
            from .bag.recorder import BagRecorder
            spec = self.runner.sim.spec
            # the same keys as an offline run's (ros2_node.bag.run_hook.run_settings), plus the node's
            settings = {"source": "flexmb node", "solver": dataclasses.asdict(spec),
                        "runner_options": dataclasses.asdict(options), "dt": repr(float(spec.dt)),
                        "integrator": spec.integrator, "tolerance": repr(float(spec.tolerance)),
                        "mode": self.p.mode, "node_name": n, "parameters": dataclasses.asdict(self.p)}
            self.recorder = BagRecorder(self.p.record, scene_path=self.p.scene, scene_text=None,
                                        settings=settings, node_name=n, qos_depth=self.p.qos_depth)
            recorded = [t for t, _ in _INPUTS] + outputs + ([T.TF] if self._pose_topics and T.TF not in outputs else [])
            for topic in recorded:       # schemas and encoders now, not at a first message mid-loop
                self.recorder.declare(topic.resolved(n), topic.type)
        self.rerun = None
        if self.p.rrd:
            from .viz.rerun_log import TwinRerunLogger
            self.rerun = TwinRerunLogger(self.model, rrd_path=self.p.rrd)
            self.rerun.log_static()

        # -- counters -----------------------------------------------------------------------------
        self.steps_advanced = 0
        self.deadline_misses = 0
        self.overruns = 0
        self._pending_steps = 0
        self._callbacks = 0
        self._new_command = False
        self._cmd_recv_wall = 0.0
        self._last_command_wall = None
        self._step_walls = _Samples()
        self._lateness = _Samples()               # realtime: step end − its deadline (s; > 0 = missed)
        self._latencies = _Samples()
        self._rtf_window = collections.deque(maxlen=1024)
        self._last_step_wall = 0.0
        self._published = 0
        self._warned: dict[str, float] = {}
        self._publish_every = 1
        self._shape_every = 0
        self._set_rates()
        self.wall_start = 0.0
        self.wall_stop = 0.0
        self.stop_requested = False
        self.log.info(f"scene '{self.model.scene.name}': {self.model.ndof} DOFs, {self.model.actuators.l0.size} "
                      f"actuators, Δt = {self.dt:g} s, mode {self.p.mode}, warm-up {self.warmup_s:.2f} s; "
                      f"commands on {T.COMMANDS.resolved(n)}, {T.ACTUATOR_COMMANDS.resolved(n)}, "
                      f"{T.TRAJECTORY.resolved(n)}")

    # -- parameters that may change at run time ----------------------------------------------------
    def _set_rates(self) -> None:
        self._publish_every = max(1, int(round(1.0 / (self.p.publish_rate * self.dt))))
        self._shape_every = 0 if self.p.shape_rate <= 0 else max(1, int(round(1.0 / (self.p.shape_rate * self.dt))))

    def _on_set_parameters(self, params):
        from rcl_interfaces.msg import SetParametersResult

        from .params import check
        try:
            for prm in params:
                setattr(self.p, prm.name, check(prm.name, prm.value))
        except FlexmbError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._set_rates()
        return SetParametersResult(successful=True)

    # -- inputs ---------------------------------------------------------------------------------------
    def _warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._warned.get(key, -math.inf) >= self.p.log_throttle:
            self._warned[key] = now
            self.log.warning(text)

    def _on_command(self, topic: T.Topic, kind: str, msg) -> None:
        t_recv = time.perf_counter()
        self._callbacks += 1
        name = topic.resolved(self.node_name)
        d = to_dict(msg) if self.recorder is not None else msg
        if self.recorder is not None:
            self.recorder.write(name, topic.type, d, self.runner.t)
        try:
            rejection = apply_message(self.runner, kind, name, d)
        except (FlexmbError, ValueError, TypeError, KeyError) as exc:
            self._warn(f"{name}:error", f"{name}: rejected: {exc}")
            rejection = True
        if rejection is not None:
            if rejection is not True:
                self._warn(f"{name}:{rejection.kind}", str(rejection))
        else:
            self._new_command = True
            self._cmd_recv_wall = t_recv
        self._last_command_wall = t_recv
        if self.p.mode == "lockstep":
            self._pending_steps += 1

    def _drain(self) -> None:
        """Run the callbacks of every message already waiting (bounded)."""
        for _ in range(32):
            before = self._callbacks
            self.executor.spin_once(timeout_sec=0.0)
            if self._callbacks == before:
                return

    # -- outputs --------------------------------------------------------------------------------------
    def _out(self, topic: T.Topic, msg, make_dict, t: float) -> None:
        """Publish ``msg`` (filled by :class:`LiveMessages`) and record ``make_dict()`` (the same
        content, from :mod:`ros2_node.messages`)."""
        pub = self._pub.get(topic.name)
        if pub is not None and msg is not None:
            pub.publish(msg)
        if self.recorder is not None:
            self.recorder.write(topic.resolved(self.node_name), topic.type, make_dict(), t)

    def _timing(self, outcome_message: str) -> M.StatusTiming:
        c = self.runner.counters
        latency = (time.perf_counter() - self._cmd_recv_wall) if self._cmd_recv_wall else 0.0
        return M.StatusTiming(step_wall_time=self._last_step_wall, steps=c.steps,
                              deadline_misses=self.deadline_misses,
                              unconverged_steps=c.failed_steps + c.flagged_steps,
                              real_time_factor=self._rtf(), command_stamp=self.runner.newest_command_stamp,
                              command_latency=latency, rejected_commands=self.runner.rejected_commands,
                              message=outcome_message)

    def _rtf(self) -> float:
        w = self._rtf_window
        if len(w) < 2 or w[-1][0] <= w[0][0]:
            return 0.0
        return (w[-1][1] - w[0][1]) / (w[-1][0] - w[0][0])

    def _publish(self, outcome_message: str, advanced: bool) -> None:
        k = self.steps_advanced
        on_command = self.p.publish_on_command and self._new_command and advanced
        due = k % self._publish_every == 0 or not advanced
        # lockstep: every step answers one command, and its status is the acknowledgement
        ack = self.p.mode == "lockstep"
        shape_due = self._shape_every and k % self._shape_every == 0
        if not (due or on_command or shape_due or ack):
            return
        s = self.runner.sample(full=bool(due or shape_due))
        t = s.t
        if not s.is_finite():       # never publish NaN (the runner rolls such steps back already)
            self._warn("nan", f"non-finite output at t = {t:.6g} s withheld")
            return
        live = self.live
        if due or on_command:
            self._out(T.JOINT_STATES, live.fill_joint_state(s), lambda: M.joint_state(s), t)
            if on_command:
                self._latencies.add(time.perf_counter() - self._cmd_recv_wall)
                self._new_command = False
        if due or on_command or ack:
            timing = self._timing(outcome_message)
            self._out(T.STATUS, live.fill_status(s, timing), lambda: M.status(s, timing), t)
        if due:
            self._out(T.ACTUATOR_STATES, live.fill_actuator_state(s), lambda: M.actuator_state(s), t)
            for i, topic in enumerate(self._pose_topics):
                self._out(topic, live.fill_pose(s, i), lambda i=i: M.platform_pose(s, i), t)
            if self._pose_topics:
                self._out(T.TF, live.fill_tf(s) if live.tf_msg is not None else None, lambda: M.tf(s), t)
            if self.p.publish_clock:
                self._out(T.CLOCK, live.fill_clock(t), lambda: M.clock(t), t)
            self._published += 1
        if shape_due:
            kinds, shells = self.runner.member_kinds, self.runner.shells
            self._out(T.SHAPE, live.fill_shape(s, kinds, shells), lambda: M.shape(s, kinds, shells), t)
            if self.rerun is not None:
                self.rerun.log_sample(s, {"step_wall_time": self._last_step_wall, "real_time_factor": self._rtf(),
                                          "message": outcome_message}, shells)

    # -- stepping -------------------------------------------------------------------------------------
    def _step(self) -> None:
        a = time.perf_counter()
        outcome = self.runner.step()
        b = time.perf_counter()
        self._last_step_wall = b - a
        self._step_walls.add(self._last_step_wall)
        if outcome.advanced:
            self.steps_advanced += 1
        else:
            self._warn("step", outcome.message)
        self._rtf_window.append((b, self.runner.t))
        self._publish(outcome.message if not outcome.converged or outcome.message else "", outcome.advanced)

    def request_stop(self, *_args) -> None:
        """SIGINT/SIGTERM: finish the current step, then close the recording and write the summary."""
        self.stop_requested = True

    def _done(self) -> bool:
        if self.stop_requested or not self.context.ok():
            return True
        return self.p.duration > 0 and self.runner.t >= self.p.duration - 0.5 * self.dt

    def spin(self) -> dict:
        """Run until ``duration`` or shutdown (SIGINT/SIGTERM); returns the summary."""
        from rclpy.executors import ExternalShutdownException

        self.wall_start = time.perf_counter()
        try:
            # publish the initial state once, so subscribers see the twin before the first command
            self._publish("", False)
            if self.p.mode == "lockstep":
                self._spin_lockstep()
            else:
                self._spin_realtime()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            self.wall_stop = time.perf_counter()
            summary = self.summary()
            self.close()
        return summary

    def _spin_realtime(self) -> None:
        dt = self.dt
        t0 = time.perf_counter()
        k = 0
        while not self._done():
            self._drain()
            self._step()
            k += 1
            deadline = t0 + k * dt
            end = time.perf_counter()
            self._lateness.add(end - deadline)
            if end > deadline:
                self.deadline_misses += 1
                if end - deadline > self.p.max_lag:   # far behind: re-anchor instead of bursting
                    self.overruns += 1
                    t0 = end - k * dt
                    continue
            # Sleep in the executor (commands are taken as they come) until shortly before the
            # deadline, then poll: the executor's timed wait wakes up to ~0.5 ms late.
            while True:
                rem = deadline - time.perf_counter()
                if rem <= 0.0 or not self.context.ok():
                    break
                self.executor.spin_once(timeout_sec=rem - _WAKE_MARGIN if rem > _WAKE_MARGIN else 0.0)

    def _spin_lockstep(self) -> None:
        last_beat = time.perf_counter()
        while not self._done():
            if self._pending_steps == 0:
                self.executor.spin_once(timeout_sec=0.05)
                if time.perf_counter() - last_beat > _HEARTBEAT:
                    # idle: repeat the status so that late joiners see the twin and its time
                    last_beat = time.perf_counter()
                    s = self.runner.sample()
                    timing = self._timing("")
                    self._out(T.STATUS, self.live.fill_status(s, timing), lambda: M.status(s, timing), s.t)
                    if self.p.publish_clock:
                        self._out(T.CLOCK, self.live.fill_clock(s.t), lambda: M.clock(s.t), s.t)
                if (self.p.idle_timeout > 0 and self._last_command_wall is not None
                        and time.perf_counter() - self._last_command_wall > self.p.idle_timeout):
                    self.log.info(f"no command for {self.p.idle_timeout} s: stopping")
                    return
                continue
            self._pending_steps -= 1
            self._step()
            last_beat = time.perf_counter()

    # -- end ------------------------------------------------------------------------------------------
    def summary(self) -> dict:
        c = self.runner.counters
        wall = max(self.wall_stop - self.wall_start, 1e-12)
        steps_wall = self._step_walls.total
        return {
            "scene": self.model.scene.name, "scene_file": str(self.scene_path), "mode": self.p.mode, "dt": self.dt,
            "node_name": self.node_name, "steps": c.steps, "steps_advanced": self.steps_advanced,
            "sim_time_s": self.runner.t, "wall_time_s": wall, "rtf": self.runner.t / wall,
            "solver_rtf": (self.runner.t / steps_wall) if steps_wall > 0 else math.inf,
            "jit_warmup_s": self.warmup_s, "deadline_misses": self.deadline_misses, "overruns": self.overruns,
            "step_wall_time_s": self._step_walls.percentiles(),
            "deadline_slack_s": self._lateness.percentiles((1, 50), sign=-1.0),
            "command_to_state_latency_s": self._latencies.percentiles(),
            "failed_steps": c.failed_steps, "flagged_steps": c.flagged_steps, "substepped_steps": c.substepped_steps,
            "commands_accepted": self.runner.schedule.accepted if self.runner.schedule else 0,
            "commands_rejected": dict(c.rejections), "published_states": self._published,
            "record": self.p.record, "rrd": self.p.rrd,
        }

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None
        if self.rerun is not None:
            self.rerun.close()
            self.rerun = None
        try:
            self.executor.remove_node(self.node)
        except Exception:
            pass
        self.node.destroy_node()


def run_node(values: dict, *, node_name: str = T.DEFAULT_NODE_NAME, ros_args: list[str] | None = None) -> dict:
    """Initialise rclpy, run one :class:`TwinNode` to its end, shut down; returns the summary."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(args=["flexmb_node"] + (["--ros-args"] + ros_args if ros_args else []), context=context)
    node = None
    try:
        node = TwinNode(values, context=context, node_name=node_name)
        # our own handlers: rclpy's do not reliably stop a loop that never blocks in the executor
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, node.request_stop)
        summary = node.spin()
    finally:
        if context.ok():
            rclpy.shutdown(context=context)
    if node is not None and node.p.summary_json:
        path = Path(node.p.summary_json)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(summary, indent=2) + "\n")
    return summary
