"""``flexmb node SCENE``: the twin as a ROS 2 node (rclpy, real DDS).

Commands in (``~/commands``, ``~/actuator_commands``, ``~/joint_trajectory``, ``~/joint_commands``),
the flexible mechanism out (``joint_states``, ``~/actuator_states``, ``~/platform_pose``, ``~/shape``,
``~/status``, ``/clock``, ``/tf``, ``/diagnostics``); names and types in :mod:`flexmb_io.topics`,
resolved by rclpy (namespace, remapping; what the recordings store). A managed (lifecycle) node
(configure = compile + warm-up, activate = step, deactivate = hold, cleanup) with the services
``~/reset``, ``~/pause``, ``~/resume`` and ``~/step`` (:class:`TwinNode`). QoS: outputs reliable,
command inputs best effort, both overridable per topic by ROS 2's ``qos_overrides.*`` parameters.

Three threads, so that the time loop never waits for the interpreter's other work:

- the **stepping thread** (:class:`~flexmb_io.realtime.Stepper`) runs the numba step (GIL
  released) paced to absolute deadlines, and copies the state into a ring of preallocated
  snapshots;
- the **executor** (the main thread, rclpy's C++ ``EventsExecutor``) validates and applies the
  command messages it receives (one lock keeps a command and a step apart) and wakes the stepping
  thread;
- the **publisher thread** turns due snapshots into messages, built once per publication (decimated
  by ``publish_rate``), publishes and records them, and reports health: ``~/status``,
  ``/diagnostics`` and a throttled warning when the twin falls behind the wall clock.

Timing. ``realtime``: the step to state n+1 must end by ``t_start + (n+1) Δt``; a waiting command
starts its step at once, otherwise a step starts ``step_margin`` before its deadline (see
:mod:`flexmb_io.realtime`). ``lockstep``: one step per received command message, deterministic, so
a lockstep run equals an offline replay of its commands (:mod:`flexmb_io.bag`). Warm-up (numba
compile or cache load) happens before the first step, outside the timed loop.
"""

from __future__ import annotations

import collections
import dataclasses
import gc
import json
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

from flexmb_core.errors import FlexmbError, excerpt, near_names, writable_file
from flexmb_core.model.compile import compile_scene
from flexmb_core.model.workspace import Workspace
from flexmb_core.report import TwinReporter
from flexmb_core.scene import load_scene
from flexmb_io import messages as M
from flexmb_io import topics as T
from flexmb_io.realtime import (IdleLatencyRequest, Samples, Snapshot, Stepper, StepperConfig,
                                fifo_priority_in_force, helper_priority, raise_to_fifo, restore_scheduling)
from flexmb_io.shells import ShellShapes
from flexmb_io.twin import RunnerOptions, TwinRunner
from flexmb_io.wire import serialize

from .convert import message_class, to_dict
from .logsink import DeferredLogger
from .params import BY_NAME, SPECS, NodeParams
from .taking import TAKE_MAX, take_waiting_received

# s a thread may hold the GIL while another waits for it (Python's default 5 ms is five steps)
_SWITCH_INTERVAL = 5.0e-5
# s of wall time the publisher thread may spend, per pass over its queue, waiting for the executor
# to finish handling a command before it builds its next message. The GIL has no priorities: a
# publication (the reporter's read and six messages, ≈ 0.18 ms of CPU at 100 Hz on the bar twin)
# that overlaps a command takes the GIL from the command's path every switch interval, which
# lengthens the answer's latency and the command's step. Measured (bar legs at 1 kHz, 30 s rounds,
# interleaved): publish_rate 10 instead of 100 gave in-node latency p99 0.33–0.53 ms against
# 0.46–1.24, client p99 1.2–2.4 ms against 1.5–3.6 (docs/benchmarks/node_ab_publish_rate.md); this
# wait, at 100 Hz, client p99 1.34–1.95 ms against 1.65–2.22, lower in each of 4 rounds, in-node
# p99 0.32–0.52 against 0.48–0.71 (node_ab_yield.md). Bounded, so that a node whose executor never
# rests (an overload) still publishes and records everything, only later.
_COMMAND_YIELD = 1.0e-3
# s of wall time between two status messages of an idle lockstep twin
_HEARTBEAT = 0.2
# s of wall time between two looks at which output topics have subscribers
_LISTENER_PERIOD = 0.5
# after a spin applied a command, take the command histories empty and spin once more (see the
# executor's comment in TwinNode.__init__); False only for benchmarks/node_overload_rss.py's
# comparison with the node before (the executor's queue then grows while the node is overloaded)
DRAIN_HISTORIES = True
# MB the resident set may grow after stepping began before the node says so (measured on an idle
# machine: flat over 8.7 min once the rings were resident, docs/benchmarks/node_rss_soak.md)
RSS_GROWTH_WARN_MB = 64.0

# topic → what apply_message calls it
_INPUTS = tuple((t, T.KINDS[t.name]) for t in T.INPUTS)
# QoS policies a qos_overrides.<topic>.publisher|subscription.<policy> parameter may set
_OVERRIDABLE = ("HISTORY", "DEPTH", "RELIABILITY", "DURABILITY")
# most steps one ~/step call takes (a call holds the twin: bounded, so the node stays responsive)
MAX_STEP_SERVICE = 10_000_000


class TwinNode:
    """The twin node, a managed (lifecycle) node. Build it, then :meth:`spin` until the duration
    ends or ROS shuts down.

    Lifecycle: *configure* loads and compiles the scene, warms the kernels up, sets the initial
    state and creates the topics; *activate* starts (or resumes) stepping; *deactivate* holds the
    twin (no steps, the state kept, commands ignored); *cleanup* drops the twin and its topics;
    *shutdown* ends the node. With ``autostart`` (the default) the node configures and activates
    itself. Services (std_srvs/Trigger unless said): ``~/reset`` (back to the initial state),
    ``~/pause`` and ``~/resume`` (hold the steps, commands still applied), ``~/step``
    (``flexmb_msgs/srv/Step``: N steps at once, while paused or in lockstep).

    Parameters
    ----------
    values : parameter values from the command line (the ``--ros-args -p`` overrides win)
    context : rclpy context (initialised by the caller)
    node_name : ROS node name (private topics live under it)
    cli_params : names given by ``-p`` in the node's ``--ros-args`` (:func:`cli_param_names`):
        one the node does not have is refused (a parameters file may address other nodes too)
    """

    def __init__(self, values: dict, *, context, node_name: str = T.DEFAULT_NODE_NAME,
                 cli_params: tuple[str, ...] = ()):
        import rclpy
        from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

        self._rclpy = rclpy
        self.context = context
        self.node = _managed_node(self, node_name, context)
        # written by a thread of its own: a stderr nobody reads must not stall the publisher
        self.log = DeferredLogger(self.node.get_logger())
        self.node_name = self.node.get_name()
        self.namespace = self.node.get_namespace()
        self.fq_name = self.node.get_fully_qualified_name()

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
            effective[spec.name] = _declare(self.node, spec, value, desc)
        _refuse_unknown_overrides(self.node, cli_params)
        self.p = NodeParams.from_values(effective)
        if self.p.mode == "lockstep" and self.p.command_source == "scene":
            raise FlexmbError("parameter 'mode': lockstep steps once per received command, so it needs "
                              "command_source 'external', got 'scene'")
        self.node.add_on_set_parameters_callback(self._on_set_parameters)
        self.frames = M.Frames(world=self.p.world_frame, prefix=frame_prefix(self.p.frame_prefix, self.namespace))

        # -- lifecycle: nothing of the twin exists until configure -----------------------------------
        self.configured = False
        self.active = False
        self.paused = False
        self.runner = None
        self.stepper = None
        self.recorder = None
        self.rerun = None
        self._pub: dict = {}
        self._subs: list = []
        self._command_subs: list = []             # (topic, kind, subscription) of the command inputs
        self._diag = None
        self._threads_started = False
        self._helper_fifo = 0               # SCHED_FIFO priority of the executor and publisher threads (0: none)
        self._publisher_fifo = 0            # the publisher's, as it found it in force
        self._executor_sched = None         # the executor thread's scheduling before, restored at the end
        self._executor_thread = None        # the thread that raised it (only it can put it back)
        self._idle_latency: IdleLatencyRequest | None = None   # cpu_dma_latency once in force (kept for the summary)
        self._publisher = None
        self._summary: dict | None = None
        self._configure_error: BaseException | None = None
        self.warmup_s = 0.0
        self._services = _Services(self)

        # -- executor: rclpy's C++ events executor, which only moves command messages in. Measured
        #    against SingleThreadedExecutor (node + 1 kHz player, 80 s each, idle machine): missed
        #    deadlines 100 vs 5153, player latency p50 1.1 vs 10.2 ms, CPU beyond the solver 63 vs
        #    90 % of a core, RSS +0.03 vs +0.96 MB. Its events queue keeps one entry per message
        #    not taken while the executor is slower than the commands (ros2_node/taking.py): hence
        #    _take_commands, which takes the command histories empty after a spin applied a command
        #    (+0.02 against +1.44 MB in 15 s, a 3 ms callback at 1 kHz, as many commands applied;
        #    benchmarks/node_overload_rss.py, README "Memory")
        from rclpy.experimental import EventsExecutor
        self.executor = EventsExecutor(context=context)
        self.executor.add_node(self.node)

        # -- counters (publisher thread) ------------------------------------------------------------
        self._callbacks = 0
        self._inbox: list = []                  # executor: (topic, kind, message, reception) not yet applied
        self._took = False                      # executor: a spin applied a command
        self._draining = False                  # executor: _take_commands is spinning
        self.commands_lost: dict[str, int] = {}      # resolved command topic → messages lost before delivery
        self._out_event = threading.Event()
        # set while the executor handles no command (cleared by a command's callback, set again
        # after the spin that ran it): the publisher thread waits for it between two messages
        self._commands_idle = threading.Event()
        self._commands_idle.set()
        self._publisher_ident = None
        self._yield_until = 0.0            # the publisher's wait budget of its current pass (perf_counter)
        # held by the executor thread from a command's reception until its answer is complete: the
        # publisher records an answered state only after its answer (it records the answer's bytes)
        self._answering = threading.Lock()
        self._last_command_wall = None          # executor: newest message received
        self._accepted_wall = 0.0               # newest accepted command's reception (publisher)
        self._latency = 0.0                     # its command→state latency, once answered
        self._latencies = Samples()
        self._rtf_window = collections.deque(maxlen=1024)
        self._published = 0
        self._listened: dict[str, bool] = {}      # topic → has subscribers (unknown: publish)
        self._live = True                         # publish (else: record only) the state at hand
        self._coalesced = 0                       # states recorded but not published: a newer one was
        self._warned: dict[str, float] = {}
        self._behind_message = ""
        # MB when stepping began, at the last health check, the most since (publisher thread)
        self._rss_start = self._rss_now = self._rss_max = 0.0
        self._last_sample = None
        self.wall_start = 0.0
        self.wall_stop = 0.0
        self._cpu_start = 0.0
        self.stop_requested = False             # SIGINT/SIGTERM
        self.shutdown_requested = False         # the lifecycle shutdown transition
        self.interrupted = False
        if self.p.autostart:
            self._autostart()

    def _autostart(self) -> None:
        """Configure and activate at once (what ``flexmb node`` does unless ``--lifecycle``); a
        configuration that fails stops the node with its message."""
        from rclpy.lifecycle import TransitionCallbackReturn

        if self.node.trigger_configure() != TransitionCallbackReturn.SUCCESS:
            err = self._configure_error
            if isinstance(err, FlexmbError):
                raise err
            raise FlexmbError(f"{self.fq_name}: configure failed: {type(err).__name__}: {err}") from err
        if self.node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
            raise FlexmbError(f"{self.fq_name}: activate failed (see the log above)")

    # -- lifecycle transitions (executor thread) ----------------------------------------------------
    def _on_configure(self) -> bool:
        """Load, compile, warm up, set the initial state, create the topics and the stepper."""
        try:
            self._configure()
        except Exception as exc:            # reported; the node stays unconfigured
            self._configure_error = exc
            self.log.error(f"configure failed: {exc}" if isinstance(exc, FlexmbError)
                           else f"configure failed: {type(exc).__name__}: {exc}")
            self._teardown()
            return False
        self.configured = True
        return True

    def _configure(self) -> None:
        from rclpy.event_handler import SubscriptionEventCallbacks
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        # -- the twin: compile, warm up, initial state (outside any timed loop) ---------------------
        overrides = {"dt": self.p.dt or None, "integrator": self.p.integrator or None}
        self.scene_path = self.p.scene
        scene = load_scene(self.p.scene, overrides)
        self.model = compile_scene(scene)
        options = RunnerOptions.from_params(self.p)
        self.runner = TwinRunner(self.model, options=options)
        t0 = time.perf_counter()
        self.runner.start()
        self.warmup_s = time.perf_counter() - t0
        self.dt = self.runner.dt

        # -- publishers / subscriptions: names resolved by rclpy (namespace, remapping); QoS from
        #    the qos_overrides.<topic>.* parameters over these defaults ------------------------------
        out_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.p.qos_depth,
                             reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
        # best effort: matches reliable and best-effort publishers alike (a reliable subscription
        # silently never hears a best-effort publisher). Keep last: a twin that falls behind a burst
        # acts on the newest commands, not on a backlog (measured under load, keep-all: player
        # latency p50 66 ms, p99 503 ms; keep-last 10: 10 / 42 ms); what this history overwrites
        # goes uncounted. With a keep-all override nothing is overwritten here and every loss
        # happens upstream, where Fast DDS sees the gap and reports lost messages (counted per
        # topic, _on_lost): a 10⁴-message burst into a slow callback, keep-last 10: 517 taken, 142
        # reported lost, 93 % unaccounted; keep-all: 5681 taken, 4032 reported lost, 2.9 %
        # unaccounted (the burst's tail, after the last delivery)
        in_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.p.qos_depth,
                            reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
        overriding = _overriding()
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
        self._names: dict[str, str] = {}          # topic as declared → as resolved
        for topic in outputs:
            pub = self.node.create_publisher(message_class(topic.type), topic.name, out_qos,
                                             qos_overriding_options=overriding)
            self._pub[topic.name] = pub
            self._names[topic.name] = pub.topic_name
        if self.p.diagnostics_rate > 0:
            self._diag = Diagnostics(self.node, out_qos, self.fq_name.lstrip("/"))
        if self.runner.schedule is not None:
            for topic, kind in _INPUTS:
                box: list = []           # the subscription, for its callback (created with it)
                cb = (lambda msg, _t=topic, _k=kind, _b=box: self._on_message(_t, _k, msg, _b[0]))
                lost = SubscriptionEventCallbacks(message_lost=lambda ev, _t=topic: self._on_lost(_t, ev))
                sub = self.node.create_subscription(message_class(topic.type), topic.name, cb, in_qos,
                                                    qos_overriding_options=overriding, event_callbacks=lost)
                box.append(sub)
                self._subs.append(sub)
                self._command_subs.append((topic, kind, sub))
                self._names[topic.name] = sub.topic_name

        # -- recording and viewing ------------------------------------------------------------------
        if self.p.record:
            from flexmb_io.bag.recorder import BagRecorder
            spec = self.runner.sim.spec
            n = self.node_name
            # the same keys as an offline run's (flexmb_io.bag.run_hook.run_settings), plus the node's
            settings = {"source": "flexmb node", "solver": dataclasses.asdict(spec),
                        "runner_options": dataclasses.asdict(options), "dt": repr(float(spec.dt)),
                        "integrator": spec.integrator, "tolerance": repr(float(spec.tolerance)),
                        "mode": self.p.mode, "node_name": n, "node_namespace": self.namespace,
                        "frames": dataclasses.asdict(self.frames), "parameters": dataclasses.asdict(self.p)}
            self.recorder = BagRecorder(self.p.record, scene_path=self.p.scene, scene_text=None,
                                        settings=settings, node_name=n, qos_depth=self.p.qos_depth)
            recorded = [t for t, _ in _INPUTS] + outputs + ([T.TF] if self._pose_topics and T.TF not in outputs else [])
            for topic in recorded:       # schemas and encoders now, not at a first message mid-loop
                self.recorder.declare(self._resolved(topic), topic.type)
        if self.p.rrd:
            from flexmb_io.viz.rerun_log import TwinRerunLogger
            self.rerun = TwinRerunLogger(self.model, rrd_path=self.p.rrd)
            self.rerun.log_static()

        # -- the publisher's own view of the state: a reporter and a workspace of its own, so it
        #    never touches the buffers the stepping thread is using -----------------------------------
        self._reporter = TwinReporter(self.model)
        self._view = _SnapshotView(self.model, Workspace(self.model))
        self._view.last = self.runner.sim.last
        # ... and the executor's, for the answers to commands whose step it ran (Stepper.submit)
        self._answer_reporter = TwinReporter(self.model)
        self._answer_view = _SnapshotView(self.model, Workspace(self.model))
        self._shells = ShellShapes(self.model)
        self._member_kinds = self.runner.member_kinds

        # -- the stepping thread (started on activate) -----------------------------------------------
        self.stepper = Stepper(self.runner, StepperConfig(
            mode=self.p.mode, publish_on_command=self.p.publish_on_command, max_lag=self.p.max_lag,
            margin=self.p.step_margin, margin_auto=self.p.step_margin_auto, duration=self.p.duration,
            cpu_affinity=_cpus(self.p.cpu_affinity),
            rt_priority=self.p.rt_priority, window=max(1, int(round(1.0 / self.dt)))), self._wake_publisher)
        self._set_rates()
        self._prime()
        self.log.info(f"scene '{self.model.scene.name}': {self.model.ndof} DOFs, {self.model.actuators.l0.size} "
                      f"actuators, Δt = {self.dt:g} s, mode {self.p.mode}, warm-up {self.warmup_s:.2f} s; "
                      f"commands on {', '.join(self._resolved(t) for t, _ in _INPUTS)}")

    def _resolved(self, topic: T.Topic) -> str:
        """A topic's name as rclpy resolved it (namespace, remapping), for the recordings."""
        name = self._names.get(topic.name)
        return name if name is not None else self.node.resolve_topic_name(topic.name)

    def _on_activate(self) -> bool:
        if not self._threads_started:
            self._start_threads()
        else:
            self.stepper.release()
        self.paused = False
        self.active = True
        return True

    def _on_deactivate(self) -> bool:
        self.active = False
        self.stepper.hold()
        return True

    def _on_cleanup(self) -> bool:
        self.active = False
        self._stop_threads()
        self._summary = self.summary()
        self._teardown()
        return True

    def _start_threads(self) -> None:
        # Everything allocated so far lives as long as the node: keep the cyclic collector off it,
        # so that no collection of the whole heap stalls a thread mid-run.
        gc.collect()
        gc.freeze()
        # The stepping thread needs the GIL for the few Python lines around its numba call: let
        # another thread keep it at most this long (default 5 ms, five steps at 1 kHz).
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(_SWITCH_INTERVAL)
        self._publisher = threading.Thread(target=self._publisher_main, name="flexmb-publish", daemon=True)
        self.wall_start = time.perf_counter()
        self._cpu_start = time.process_time()
        self._rss_start = self._rss_now = self._rss_max = _rss_mb()
        self.stepper.start()
        self._raise_helpers()
        self._request_idle_latency()
        self._publisher.start()
        self._threads_started = True
        for w in self.stepper.warnings:
            self.log.warning(w)
        for note in self.stepper.notes:
            self.log.info(note)

    def _raise_helpers(self) -> None:
        """``rt_threads: node``: the executor (this thread: the node starts its threads from it, at
        start or on the lifecycle's activation) and the publisher on SCHED_FIFO just below the stepping
        thread, which waits for them when they hold the GIL or the step lock (see
        :data:`flexmb_io.realtime.HELPER_PRIORITY_BELOW`)."""
        self._helper_fifo = 0
        if self.p.mode != "realtime" or self.p.rt_threads != "node" or not self.stepper.fifo_priority:
            return
        prio = helper_priority(self.stepper.fifo_priority)
        self._executor_sched = raise_to_fifo(prio)
        if self._executor_sched is None:
            self.stepper.warnings.append(f"the executor thread could not join the stepping thread on SCHED_FIFO "
                                         f"(priority {prio}); it keeps the normal scheduler")
            return
        self._executor_thread = threading.get_ident()
        self._helper_fifo = prio
        self.stepper.notes.append(f"executor and publisher threads on SCHED_FIFO priority {prio}")

    def _request_idle_latency(self) -> None:
        """``cpu_dma_latency`` ≥ 0 (realtime): hold the PM QoS request while the threads run (see
        :class:`flexmb_io.realtime.IdleLatencyRequest`); a refusal is a warning."""
        if self.p.mode != "realtime" or self.p.cpu_dma_latency < 0 or (self._idle_latency and self._idle_latency.held):
            return
        request = IdleLatencyRequest(self.p.cpu_dma_latency)
        refused = request.acquire()
        if refused:
            self.stepper.warnings.append(f"cpu_dma_latency {self.p.cpu_dma_latency} µs not applied ({refused}); the "
                                         "CPUs keep their idle states")
            return
        self._idle_latency = request
        self.stepper.notes.append(f"PM QoS: CPU idle-state exit latency ≤ {self.p.cpu_dma_latency} µs while the "
                                  "twin runs")

    def _stop_threads(self) -> None:
        if not self._threads_started:
            return
        self.stepper.stop()
        if self._idle_latency is not None:
            self._idle_latency.release()
        self.wall_stop = time.perf_counter()
        self._publisher.join(10.0)
        self._drain_outbox()            # anything the publisher had not reached (it stopped)
        if self._executor_sched is not None and threading.get_ident() == self._executor_thread:
            restore_scheduling(self._executor_sched)
            self._executor_sched = None
        sys.setswitchinterval(self._switch)
        gc.unfreeze()
        self._threads_started = False

    def _teardown(self) -> None:
        """Drop what configure made (topics, recording, rerun log, the twin)."""
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None
        if self.rerun is not None:
            self.rerun.close()
            self.rerun = None
        for pub in self._pub.values():
            self.node.destroy_publisher(pub)
        for sub in self._subs:
            self.node.destroy_subscription(sub)
        if self._diag is not None:
            self.node.destroy_publisher(self._diag._pub)
        self._pub, self._subs, self._diag = {}, [], None
        self._command_subs = []
        self._inbox.clear()
        self._listened = {}
        self.stepper = None
        self.runner = None
        self.configured = False

    # -- parameters that may change at run time ----------------------------------------------------
    def _set_rates(self) -> None:
        cfg = self.stepper.cfg
        cfg.publish_every = max(1, int(round(1.0 / (self.p.publish_rate * self.dt))))
        cfg.shape_every = 0 if self.p.shape_rate <= 0 else max(1, int(round(1.0 / (self.p.shape_rate * self.dt))))
        cfg.clock_every = max(1, int(round(1.0 / (self.p.clock_rate * self.dt)))) if self.p.publish_clock else 0
        cfg.publish_on_command = self.p.publish_on_command

    def _on_set_parameters(self, params):
        from rcl_interfaces.msg import SetParametersResult

        from .params import check
        try:
            for prm in params:
                if prm.name in BY_NAME:       # else ROS's own (use_sim_time, qos_overrides.*)
                    setattr(self.p, prm.name, check(prm.name, prm.value))
        except FlexmbError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if getattr(self, "stepper", None) is not None:
            self._set_rates()
        return SetParametersResult(successful=True)

    # -- inputs (executor thread): validate, apply, wake the stepping thread -----------------------------
    def _warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._warned.get(key, -math.inf) >= self.p.log_throttle:
            self._warned[key] = now
            self.log.warning(text)

    def _on_message(self, topic: T.Topic, kind: str, msg, sub) -> None:
        """A command subscription's callback: applied at once, or filed while _take_commands spins.

        The executor hands over a message without the time DDS received it (rclpy 9.1.2's
        ``EventsExecutor`` fails on callbacks that take the message info: "SystemError: null
        argument to internal routine"), so its arrival is the callback's time — unless more
        commands wait in its history: then the executor was late, the message came before the
        first of them, and all are filed with their receptions for :meth:`_take_commands` (after
        this spin), the first at the earlier of the callback's time and the next one's reception."""
        t_recv = time.perf_counter()
        self._commands_idle.clear()
        if self._draining:
            self._inbox.append((topic, kind, msg, t_recv))
            return
        self._took = True
        waiting = take_waiting_received(sub, TAKE_MAX) if DRAIN_HISTORIES else ()
        if waiting:
            self._inbox.append((topic, kind, msg, min(t_recv, waiting[0][1])))
            self._inbox.extend((topic, kind, m, t) for m, t in waiting)
            return
        self._on_command(topic, kind, msg, t_recv)

    def _take_commands(self) -> None:
        """After a spin applied or filed a command (executor thread): every command subscription's
        history is taken empty here (at most ``TAKE_MAX`` messages each, with their receptions:
        :func:`~ros2_node.taking.take_waiting_received`) and the commands are applied in order of
        arrival per topic. When more than one was waiting — a backlog, the sign of an
        executor slower than its commands — one non-blocking spin first runs the executor's queue:
        its entries for the messages just taken, or overwritten, now find nothing and are dropped (a
        command that arrived meanwhile is filed after them). Without this an overloaded executor
        keeps one queue entry per command it never took (the executor's comment in ``__init__``).
        A single waiting command is applied at once, without the spin (≈ 0.1 ms): measured on a calm
        machine, spinning for it too raised the node's p99 latency from 1.4 to 4.4 ms
        (``benchmarks/node_overload_rss.py --rounds 0 --bare 0 --latency-runs 5``). On a node
        that keeps up the histories are mostly empty: one take per command topic (a few µs each)."""
        self._took = False
        inbox = self._inbox
        for topic, kind, sub in self._command_subs:
            inbox.extend((topic, kind, m, t) for m, t in take_waiting_received(sub, TAKE_MAX))
        if not inbox:
            return               # the histories were empty: the next spin drops any stale entry
        if len(inbox) > 1:       # a backlog: drop the executor's stale entries before applying
            self._draining = True
            try:
                self.executor.spin_once(timeout_sec=0.0)
            finally:
                self._draining = False
        self._apply_inbox()

    def _apply_inbox(self) -> None:
        """The filed commands in order, and then their steps (realtime: :meth:`Stepper.submit`'s
        ``steps``, run by the newest): a backlog's older commands are already late, and a step
        for each ran the twin on targets extrapolated from samples up to tens of ms old (1 kHz
        under load, README "Bare streams over real DDS")."""
        inbox = self._inbox
        last = len(inbox) - 1
        try:
            for i, (topic, kind, msg, t_recv) in enumerate(inbox):
                self._on_command(topic, kind, msg, t_recv, steps=len(inbox) if i == last else 0)
        finally:
            inbox.clear()

    def _on_command(self, topic: T.Topic, kind: str, msg, t_recv: float, steps: int = 1) -> None:
        if not self.active:
            self._warn("inactive", f"{self._names[topic.name]}: ignored: the node is inactive (lifecycle); "
                       "activate it to command the twin")
            return
        self._callbacks += 1
        self._last_command_wall = t_recv
        d = to_dict(msg) if self.recorder is not None else msg
        with self._answering:
            snap = self.stepper.submit(self._names[topic.name], kind, d, t_recv, topic, steps=steps)
            if snap is None or not snap.answered:
                return
            self._answer(snap)
        if snap.wake:
            self._wake_publisher()

    def _on_lost(self, topic: T.Topic, event) -> None:
        """Fast DDS saw a gap in a command topic's samples: commands the publisher sent that never
        reached this subscription (its history or the network dropped them). Counted per topic and
        warned of (throttled); the twin holds what it had."""
        name = self._names.get(topic.name, topic.name)
        n = int(event.total_count_change)
        self.commands_lost[name] = self.commands_lost.get(name, 0) + n
        self._warn(f"lost:{name}", f"{name}: {self.commands_lost[name]} commands lost before delivery so far "
                   "(sent faster than the twin takes them, or dropped by the network); the twin acts on "
                   "those it receives")

    def _answer(self, snap: Snapshot) -> None:
        """The answer to a command whose step ran on this (the executor's) thread: status (the
        acknowledgement, echoing its stamp) and joint states, at once. Its own reporter and
        messages: the publisher thread's are not touched. The serialized messages are kept on the
        snapshot (``snap.answer``): the publisher records those bytes, what went out, instead of
        reading the state and building both again."""
        view = self._answer_view
        view.state, view.last = snap.state, snap.result
        s = self._answer_reporter.read(view, False)
        if not s.is_finite():
            return                       # the publisher thread warns of it when it records it
        self._latency = time.perf_counter() - snap.cmd_recv_wall
        self._latencies.add(self._latency)
        # the publisher has not seen this command's event yet: its age counts from now on
        self._accepted_wall = max(self._accepted_wall, snap.cmd_recv_wall)
        recording = self.recorder is not None
        status = joints = None
        if recording or self._listened.get(T.STATUS.name, True):
            status = serialize(T.STATUS.type, M.status(s, self._timing(snap, snap.message), self.frames))
            if self._listened.get(T.STATUS.name, True):
                self._pub[T.STATUS.name].publish(status)
        if recording or self._listened.get(T.JOINT_STATES.name, True):
            joints = serialize(T.JOINT_STATES.type, M.joint_state(s, self.frames))
            if self._listened.get(T.JOINT_STATES.name, True):
                self._pub[T.JOINT_STATES.name].publish(joints)
        snap.answer = (status, joints)

    # -- outputs (publisher thread) ------------------------------------------------------------------------
    def _wake_publisher(self) -> None:
        self._out_event.set()

    def _out(self, topic: T.Topic, build, t: float) -> None:
        """Serialize ``build()`` (a :mod:`flexmb_io.messages` message) once, publish the bytes when the
        topic has subscribers and record the same bytes (nothing is built for neither).

        One form, one serialization (issue 14): the former path filled an rclpy message for the wire
        and built a dict for the bag, serialized twice. Per publication (build + serialize +
        publish + record, ``benchmarks/message_path.py``): see :mod:`flexmb_io.wire`."""
        pub = self._pub.get(topic.name)
        live = pub is not None and self._live and self._listened.get(topic.name, True)
        if not live and self.recorder is None:
            return
        self._yield_to_commands()
        data = serialize(topic.type, build())
        if live:
            pub.publish(data)
        if self.recorder is not None:
            self.recorder.write_cdr(self._resolved(topic), topic.type, data, t)

    def _yield_to_commands(self) -> None:
        """On the publisher thread, before a piece of its work: while the executor handles a command,
        wait for it (GIL released), within the pass's budget (:data:`_COMMAND_YIELD`)."""
        if self._commands_idle.is_set() or threading.get_ident() != self._publisher_ident:
            return
        wait = self._yield_until - time.perf_counter()
        if wait > 0.0:
            self._commands_idle.wait(wait)

    def _rtf(self) -> float:
        w = self._rtf_window
        if len(w) < 2 or w[-1][0] <= w[0][0]:
            return 0.0
        return (w[-1][1] - w[0][1]) / (w[-1][0] - w[0][0])

    def _timing(self, snap: Snapshot, outcome_message: str) -> M.StatusTiming:
        now = time.perf_counter()
        age = (now - self._accepted_wall) if self._accepted_wall else 0.0
        st = self.stepper.stats
        return M.StatusTiming(step_wall_time=snap.step_wall, steps=snap.steps,
                              deadline_misses=st.deadline_misses,
                              unconverged_steps=snap.failed_steps + snap.flagged_steps,
                              real_time_factor=self._rtf(), command_stamp=snap.newest_stamp,
                              command_latency=self._latency, command_age=age, rejected_commands=snap.rejected,
                              message=outcome_message or self._behind_message)

    def _on_command_event(self, topic_name: str, kind: str, d, t_applied: float, rejection,
                          recv_wall: float, topic: T.Topic, arrival: float | None) -> None:
        """A command applied at simulated time ``t_applied``: record it with that log time (what a
        replay re-applies before the same step) and its arrival (twin time, see
        :meth:`flexmb_io.realtime.Stepper._arrival`) as its publish time, and warn of a rejection."""
        if self.recorder is not None:
            self.recorder.write(topic_name, topic.type, d, t_applied, arrival)
        if rejection is None:
            self._accepted_wall = max(self._accepted_wall, recv_wall)
        elif isinstance(rejection, str):
            self._warn(f"{topic_name}:error", rejection)
        else:
            self._warn(f"{topic_name}:{rejection.kind}", str(rejection))

    def _record_answer(self, answer: tuple, t: float) -> None:
        """Record the status and joint states an answer published (their bytes), when recording."""
        if self.recorder is None:
            return
        for topic, data in zip((T.STATUS, T.JOINT_STATES), answer):
            if data is not None:
                self.recorder.write_cdr(self._resolved(topic), topic.type, data, t)

    def _publish(self, snap: Snapshot) -> None:
        answer = None
        if snap.answered:
            with self._answering:        # its answer is complete (the executor holds this meanwhile)
                answer = snap.answer
        if answer is not None and snap.answered_only:
            # answered and nothing else due: record what the answer published, as it went out
            t = float(snap.state.t)
            self._rtf_window.append((snap.end_wall, t))
            self._record_answer(answer, t)
            self._last_sample = snap
            return
        self._yield_to_commands()
        view = self._view
        view.state, view.last = snap.state, snap.result if snap.result is not None else view.last
        full = bool(snap.due or snap.shape_due)
        s = self._reporter.read(view, full)
        if full:
            self._shells.read(snap.state.q)
        t = s.t
        self._rtf_window.append((snap.end_wall, t))
        if not s.is_finite():       # never publish NaN (the runner rolls such steps back already)
            self._warn("nan", f"non-finite output at t = {t:.6g} s withheld")
            return
        frames = self.frames
        message = snap.message
        answer_due = snap.on_command and not snap.answered
        if answer_due:              # the state that answers a command: its latency, measured here
            self._latency = time.perf_counter() - snap.cmd_recv_wall
            self._latencies.add(self._latency)
        if answer is not None:
            # answered on the command's thread and also due: the answer went out already, its
            # bytes are what is recorded (and not published a second time)
            self._record_answer(answer, t)
        else:
            # a snapshot answered on the command's thread is only recorded here (unless also due)
            live_now = self._live
            self._live = live_now and (snap.due or answer_due or snap.ack)
            if snap.due or snap.on_command or snap.ack:
                # the status first: it echoes the command's stamp, the acknowledgement clients wait for
                timing = self._timing(snap, message)
                self._out(T.STATUS, lambda: M.status(s, timing, frames), t)
            if snap.due or snap.on_command:
                self._out(T.JOINT_STATES, lambda: M.joint_state(s, frames), t)
            self._live = live_now
        if snap.due:
            self._out(T.ACTUATOR_STATES, lambda: M.actuator_state(s, frames), t)
            for i, topic in enumerate(self._pose_topics):
                self._out(topic, lambda i=i: M.platform_pose(s, i, frames), t)
            if self._pose_topics:
                self._out(T.TF, lambda: M.tf(s, frames), t)
            self._published += 1
        if snap.shape_due:
            kinds, shells = self._member_kinds, self._shells
            self._out(T.SHAPE, lambda: M.shape(s, kinds, shells, frames), t)
            if self.rerun is not None:
                self.rerun.log_sample(s, {"step_wall_time": snap.step_wall, "real_time_factor": self._rtf(),
                                          "message": message}, shells)
        if not snap.advanced and message:
            self._warn("step", message)
        self._last_sample = snap

    def _refresh_listeners(self) -> None:
        """Which output topics have subscribers: a message nobody takes is neither filled nor
        published (serializing it costs as much as the solver step). Asked twice a second."""
        self._listened = {name: pub.get_subscription_count() > 0 for name, pub in self._pub.items()}

    def _drain_outbox(self) -> int:
        """Record every queued event in order and publish them; when several states queued up (the
        publisher fell behind), only the newest goes out live — the older ones are stale by then —
        and every one is still recorded. Returns how many events were handled."""
        out = self.stepper.outbox
        self._yield_until = time.perf_counter() + _COMMAND_YIELD
        events = []
        while out:
            events.append(out.popleft())
        slots = self.stepper.slots

        # the newest state this thread publishes (an answered one only is recorded, unless also due)
        newest = max((i for i, ev in enumerate(events) if ev[0] == "out" and slots[ev[1]].seq == ev[2]
                      and not slots[ev[1]].answered_only), default=-1)
        newest_clock = max((i for i, ev in enumerate(events) if ev[0] == "clock"), default=-1)
        for i, ev in enumerate(events):
            if ev[0] == "cmd":
                self._on_command_event(*ev[1:])
                continue
            if ev[0] == "clock":
                self._live, t = i == newest_clock, ev[1]
                self._out(T.CLOCK, lambda: M.clock(t), t)
                continue
            snap = slots[ev[1]]
            if snap.seq != ev[2]:
                # the stepping thread lapped the ring: this publication was overwritten
                self.stepper.stats.dropped_snapshots += 1
                continue
            self._live = i == newest
            if not self._live and not snap.answered_only:
                self._coalesced += 1
            self._publish(snap)
        self._live = True
        return len(events)

    def _check_health(self) -> None:
        """The throttled 'behind' warning and the reason in ``status.message``."""
        st = self.stepper.stats
        msg = ""
        if st.recent_misses:
            window = min(self.stepper.cfg.window, self.runner.counters.steps)
            msg = (f"behind real time: {st.recent_misses} of the last {window} steps missed their "
                   f"deadline ({st.deadline_misses} in total, {st.overruns} re-anchored); step wall time p99 "
                   f"{1e3 * self.stepper.step_walls.percentiles((99,), last=window)['p99']:.3f} ms for Δt = "
                   f"{1e3 * self.dt:g} ms")
        if st.dropped_publications:
            msg = (msg + "; " if msg else "") + (f"publisher behind: {st.dropped_publications} publications "
                                                 "dropped")
        rss = self._rss_now = _rss_mb()
        self._rss_max = max(self._rss_max, rss)
        if rss - self._rss_start > RSS_GROWTH_WARN_MB:
            msg = (msg + "; " if msg else "") + (
                f"memory: resident set {rss:.0f} MB, {rss - self._rss_start:.0f} MB more than when stepping "
                "began (not expected, README 'Memory'; restarting the node gives it back)")
        if msg:
            self._warn("behind", msg)
        self._behind_message = msg

    def _publisher_main(self) -> None:
        """The publisher thread: publish what the stepping thread queues, report health."""
        if self._helper_fifo:
            raise_to_fifo(self._helper_fifo)
        self._publisher_fifo = fifo_priority_in_force()
        self._publisher_ident = threading.get_ident()
        period = 1.0 / self.p.diagnostics_rate if self.p.diagnostics_rate > 0 else math.inf
        next_diag = time.perf_counter() + period
        last_beat = time.perf_counter()
        next_listeners = last_beat
        try:
            while True:
                self._out_event.wait(0.05)
                self._out_event.clear()
                handled = self._drain_outbox()
                now = time.perf_counter()
                if handled:
                    last_beat = now
                if now >= next_listeners:
                    next_listeners = now + _LISTENER_PERIOD
                    self._refresh_listeners()
                if now >= next_diag:
                    next_diag = now + period
                    self._check_health()
                    if self._diag is not None:
                        self._diag.publish(self)
                if self.p.mode == "lockstep" and self.active and now - last_beat > _HEARTBEAT:
                    last_beat = now
                    self._heartbeat()
                if self.stepper.finished.is_set() and not self.stepper.outbox:
                    return
        except Exception as exc:           # reported and stops the node; never a silent dead thread
            self.publisher_error = exc
            self.stop_requested = True

    publisher_error: BaseException | None = None

    def _heartbeat(self) -> None:
        """Idle lockstep twin: repeat the status so that late joiners see the twin and its time."""
        snap = self._last_sample
        if snap is None:
            return
        view = self._view
        view.state = snap.state
        s = self._reporter.read(view, False)
        timing = self._timing(snap, "")
        self._out(T.STATUS, lambda: M.status(s, timing, self.frames), s.t)
        if self.p.publish_clock:
            self._out(T.CLOCK, lambda: M.clock(s.t), s.t)

    def _prime(self) -> None:
        """Build and serialize every output message once from the initial state (nothing is published
        or recorded): the first publication then neither generates a serializer nor loads a kernel
        while the stepping thread runs."""
        view = self._view
        view.state = self.runner.sim.state
        s = self._reporter.read(view, True)
        self._shells.read(view.state.q)
        frames = self.frames
        built = [(T.JOINT_STATES, M.joint_state(s, frames)), (T.STATUS, M.status(s, M.StatusTiming(), frames)),
                 (T.ACTUATOR_STATES, M.actuator_state(s, frames)), (T.CLOCK, M.clock(s.t)),
                 *((T.PLATFORM_POSE, M.platform_pose(s, i, frames)) for i in range(len(self._pose_topics)))]
        if self._pose_topics:
            built.append((T.TF, M.tf(s, frames)))
        if self.stepper.cfg.shape_every:
            built.append((T.SHAPE, M.shape(s, self._member_kinds, self._shells, frames)))
        for topic, msg in built:
            serialize(topic.type, msg)

    # -- running ------------------------------------------------------------------------------------------
    def request_stop(self, *_args) -> None:
        """SIGINT/SIGTERM: finish the current step, then close the recording and write the summary."""
        self.stop_requested = True

    def _done(self) -> bool:
        if self.stop_requested or self.shutdown_requested or not self.context.ok():
            return True
        if self.stepper is not None and self.stepper.finished.is_set():
            return True                      # duration reached (or the stepping thread failed)
        if (self.p.mode == "lockstep" and self.p.idle_timeout > 0 and self._last_command_wall is not None
                and time.perf_counter() - self._last_command_wall > self.p.idle_timeout):
            self.log.info(f"no command for {self.p.idle_timeout} s: stopping")
            return True
        return False

    def spin(self) -> dict:
        """Run until ``duration`` or shutdown (SIGINT/SIGTERM); returns the summary."""
        from rclpy.executors import ExternalShutdownException

        errors = ()
        try:
            while not self._done():
                self.executor.spin_once(timeout_sec=0.05)
                if self._took and DRAIN_HISTORIES:
                    self._take_commands()
                if not self._commands_idle.is_set():
                    self._commands_idle.set()
        except (KeyboardInterrupt, ExternalShutdownException):
            self.stop_requested = True
        finally:
            self.interrupted = self.stop_requested or not self.context.ok()
            if self.configured:
                self._stop_threads()
                errors = (("stepping", self.stepper.error), ("publisher", self.publisher_error))
                self._summary = self.summary()
            summary = self._summary or self.summary()
            self.close()
        for what, err in errors:
            if err is not None:
                raise FlexmbError(f"the {what} thread stopped: {type(err).__name__}: {err}") from err
        return summary

    # -- end ------------------------------------------------------------------------------------------
    def summary(self) -> dict:
        if self.runner is None:               # never configured (or cleaned up without a run)
            return {"node_name": self.node_name, "namespace": self.namespace, "configured": False,
                    "interrupted": self.interrupted}
        c = self.runner.counters
        st = self.stepper.stats
        wall = max(self.wall_stop - self.wall_start, 1e-12)
        steps_wall = self.stepper.step_walls.total
        return {
            "scene": self.model.scene.name, "scene_file": str(self.scene_path), "mode": self.p.mode, "dt": self.dt,
            "node_name": self.node_name, "namespace": self.namespace, "steps": c.steps, "steps_advanced": st.steps_advanced,
            "sim_time_s": self.runner.t, "wall_time_s": wall, "rtf": self.runner.t / wall,
            "solver_rtf": (self.runner.t / steps_wall) if steps_wall > 0 else math.inf,
            "jit_warmup_s": self.warmup_s, "deadline_misses": st.deadline_misses,
            "deadline_misses_started_late": st.misses_started_late,
            "deadline_misses_overran": st.misses_overran, "overruns": st.overruns,
            "step_margin_s": self.stepper.margin, "step_margin_auto": self.p.step_margin_auto,
            "fifo_priority": {"stepping": self.stepper.fifo_priority, "executor": self._helper_fifo,
                              "publisher": self._publisher_fifo},
            "cpu_dma_latency_us": self._idle_latency.us if self._idle_latency is not None else None,
            "dropped_publications": st.dropped_publications, "coalesced_publications": self._coalesced,
            "commands_waited": st.commands_waited,
            "step_wall_time_s": self.stepper.step_walls.percentiles(),
            "newton_iterations": _iterations(self.stepper.iterations),
            "deadline_slack_s": self.stepper.lateness.percentiles((1, 50), sign=-1.0),
            "command_to_state_latency_s": self._latencies.percentiles(),
            "failed_steps": c.failed_steps, "flagged_steps": c.flagged_steps, "substepped_steps": c.substepped_steps,
            "commands_accepted": self.runner.schedule.accepted if self.runner.schedule else 0,
            "commands_rejected": dict(c.rejections), "commands_lost": dict(self.commands_lost),
            "published_states": self._published,
            "faults": dict(c.faults), "stopped": c.stopped,
            "cpu_time_s": self._cpu_times(wall),
            "rss_mb": {"start": self._rss_start, "max": self._rss_max, "end": _rss_mb()},
            "record": self.p.record, "rrd": self.p.rrd, "interrupted": self.interrupted,
            "log_lines_dropped": self.log.dropped,
        }

    def _cpu_times(self, wall: float) -> dict:
        """CPU time of the node process over the run and of the solver's steps (s), and the
        difference as a fraction of one core (what the node costs beyond the solver)."""
        proc = time.process_time() - self._cpu_start
        solver = self.stepper.step_walls.total
        return {"process": proc, "solver_steps": solver, "beyond_solver_core_fraction": (proc - solver) / wall}

    def close(self) -> None:
        self._teardown()
        self.log.close()
        try:
            self.executor.remove_node(self.node)
        except Exception:
            pass
        self.node.destroy_node()


class _SnapshotView:
    """What :meth:`TwinReporter.read` reads of a :class:`Simulator`, over a snapshot's state (the
    publisher's own workspace, so the stepping thread's buffers are never shared)."""

    def __init__(self, model, ws):
        self.model = model
        self.ws = ws
        self.state = None
        self.last = None


def _cpus(text: str) -> tuple[int, ...]:
    """``cpu_affinity`` ("0,1" or "") as CPU ids."""
    if not text.strip():
        return ()
    try:
        cpus = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise FlexmbError(f"parameter 'cpu_affinity': expected comma-separated CPU ids such as '1' or '0,1', "
                          f"got {text[:40]!r}") from None
    if any(c < 0 for c in cpus):
        raise FlexmbError(f"parameter 'cpu_affinity': CPU ids are ≥ 0, got {text[:40]!r}")
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    outside = [c for c in cpus if allowed and c not in allowed]
    if outside:         # the OS would pin to the rest, or refuse: neither is what was asked
        raise FlexmbError(f"parameter 'cpu_affinity': CPU {outside[0]} is not one this process may run on "
                          f"(allowed: {allowed[:16]}{' …' if len(allowed) > 16 else ''}), got {text[:40]!r}")
    return cpus


class Diagnostics:
    """``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``): solver health, deadlines, commands."""

    def __init__(self, node, qos, node_name: str):
        """``node_name``: the node's fully qualified name without its leading '/' (each entry's
        name starts with it, so twins in two namespaces stay apart on the global topic)."""
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

        self._types = (DiagnosticArray, DiagnosticStatus, KeyValue)
        self._pub = node.create_publisher(DiagnosticArray, T.DIAGNOSTICS.name, qos,
                                          qos_overriding_options=_overriding())
        self._name = node_name

    def publish(self, twin: "TwinNode") -> None:
        DiagnosticArray, DiagnosticStatus, KeyValue = self._types
        snap = twin._last_sample
        st = twin.stepper.stats
        c = twin.runner.counters
        walls = twin.stepper.step_walls.percentiles((50, 99), last=twin.stepper.cfg.window)
        ok, warn, error = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR

        def entry(what, level, message, values):
            return DiagnosticStatus(level=level, name=f"{self._name}: {what}", message=message,
                                    hardware_id=twin.model.scene.name,
                                    values=[KeyValue(key=k, value=str(v)) for k, v in values])

        res = snap.result if snap is not None else None
        converged = bool(res.converged) if res is not None else True
        failed = c.failed_steps + c.flagged_steps
        solver = entry("solver", ok if converged and not failed else (warn if converged else error),
                       "converged" if converged else (snap.message or "last step did not converge"),
                       [("converged", converged), ("newton_iterations", getattr(res, "iterations", 0)),
                        ("residual", getattr(res, "residual", 0.0)), ("steps", c.steps),
                        ("failed_steps", c.failed_steps), ("flagged_steps", c.flagged_steps),
                        ("substepped_steps", c.substepped_steps), ("sim_time", twin.runner.t)])
        behind = st.recent_misses > 0 or st.dropped_publications > 0
        timing = entry("deadlines", warn if behind else ok, twin._behind_message or "keeping real time",
                       [("deadline_misses", st.deadline_misses), ("recent_misses", st.recent_misses),
                        ("misses_started_late", st.misses_started_late),
                        ("misses_overran", st.misses_overran),
                        ("window_steps", twin.stepper.cfg.window), ("overruns", st.overruns),
                        ("dropped_publications", st.dropped_publications), ("step_wall_p50_s", walls["p50"]),
                        ("step_wall_p99_s", walls["p99"]), ("real_time_factor", twin._rtf()), ("dt", twin.dt),
                        ("rss_mb", round(twin._rss_now, 1)), ("rss_at_start_mb", round(twin._rss_start, 1))])
        rej, lost = dict(c.rejections), dict(twin.commands_lost)
        said = ([f"{sum(rej.values())} rejected"] if rej else []) + ([f"{sum(lost.values())} lost"] if lost else [])
        cmds = entry("commands", warn if said else ok, ", ".join(said) or "all accepted",
                     [("accepted", twin.runner.schedule.accepted if twin.runner.schedule else 0),
                      ("latency_s", twin._latency)] + [(f"rejected_{k}", v) for k, v in sorted(rej.items())]
                     + [(f"lost_{k}", v) for k, v in sorted(lost.items())])
        level = error if c.stopped else (warn if c.faults else ok)
        limits = entry("limits", level, c.stopped or (c.last_message if c.faults else "within the scene's limits"),
                       [(f"faults_{k}", v) for k, v in sorted(c.faults.items())] + [("stopped", bool(c.stopped))])
        msg = DiagnosticArray(status=[solver, timing, cmds, limits])
        now = twin.node.get_clock().now().to_msg()
        msg.header.stamp = now
        self._pub.publish(msg)


def _rss_mb() -> float:
    """Resident set size of this process (MB): ``/proc/self/statm`` (Linux), else the peak."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        import resource
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _declare(node, spec, value, descriptor):
    """Declare one parameter; a value out of its range or of the wrong type (a flag or ``-p``) is a
    :class:`FlexmbError` naming the parameter, the value and what was expected, not rclpy's traceback."""
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

    try:
        return node.declare_parameter(spec.name, value, descriptor).value
    except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
        if isinstance(exc, InvalidParameterTypeException):
            expected = f"a {type(spec.default).__name__}"
        elif spec.low is not None:
            expected = f"a value in [{spec.low:g}, {spec.high:g}]"
        else:
            expected = f"one of {list(spec.choices)}" if spec.choices else "a valid value"
        raise FlexmbError(f"parameter '{spec.name}' (flag --{spec.name.replace('_', '-')} or -p "
                          f"{spec.name}:=...): expected {expected}; rclpy: {str(exc)[:160]}") from None


def cli_param_names(ros_args: list[str] | None, node_name: str) -> tuple[str, ...]:
    """The parameter names ``-p``/``--param`` items of ``ros_args`` give this node: ``name:=value``
    and ``node_name:name:=value`` (another node's are not this node's)."""
    args, names = list(ros_args or []), []
    for flag, item in zip(args, args[1:]):
        if flag not in ("-p", "--param") or ":=" not in item:
            continue
        target, _, name = item.split(":=", 1)[0].rpartition(":")
        if target in ("", node_name):
            names.append(name)
    return tuple(names)


def _refuse_unknown_overrides(node, names: tuple[str, ...]) -> None:
    """A ``-p name:=value`` for this node that names no parameter of it is a
    :class:`FlexmbError`, not silently ignored as rclpy does for undeclared names: a typo would
    otherwise run the twin on a default the user meant to change. ROS's own parameters
    (``use_sim_time``, …, declared by rclpy before ours) and ``qos_overrides.*`` (declared with the
    topics) are known; a ``--params-file`` is not checked (one file often serves several nodes)."""
    unknown = sorted(name for name in set(names)
                     if not node.has_parameter(name) and not name.startswith("qos_overrides."))
    if not unknown:
        return
    name = unknown[0]
    close = near_names(name, BY_NAME, n=3)
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    more = f" (and {len(unknown) - 1} more unknown)" if len(unknown) > 1 else ""
    raise FlexmbError(f"parameter {name[:60]!r} (-p {name[:60]}:=...): no parameter of the twin node has this "
                      f"name{more}{hint} (`flexmb node --help` lists them all)")


def _iterations(samples: Samples) -> dict:
    """Newton iterations per step: mean over the run, p50/p99/max over the newest steps the
    buffer holds."""
    out = samples.percentiles()
    out["mean"] = samples.total / samples.count if samples.count else 0.0
    return out


def run_node(values: dict, *, node_name: str = T.DEFAULT_NODE_NAME, ros_args: list[str] | None = None) -> dict:
    """Initialise rclpy, run one :class:`TwinNode` to its end, shut down; returns the summary."""
    import rclpy
    from rclpy.context import Context
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    if values.get("summary_json"):
        writable_file(values["summary_json"], "summary_json")     # before the run, not at its end
    context = Context()
    try:
        rclpy.init(args=["flexmb_node"] + (["--ros-args"] + ros_args if ros_args else []), context=context)
    except (_rclpy.RCLError, _rclpy.UnknownROSArgsError) as exc:
        raise FlexmbError(f"--ros-args {excerpt(' '.join(ros_args or []))}: {str(exc).splitlines()[0][:200]}") from None
    node = None
    try:
        node = TwinNode(values, context=context, node_name=node_name, cli_params=cli_param_names(ros_args, node_name))
        # our own handlers: rclpy's do not reliably stop a loop that never blocks in the executor
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, node.request_stop)
        summary = node.spin()
    finally:
        if context.ok():
            rclpy.shutdown(context=context)
    if node is not None and node.p.summary_json:
        Path(node.p.summary_json).write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def frame_prefix(value: str, namespace: str) -> str:
    """The ``frame_prefix`` parameter's prefix: ``auto`` → the namespace without its leading '/'
    plus '/' (``/robot1`` → ``robot1/``; the root namespace → ``''``); anything else as given."""
    if value != "auto":
        return value
    ns = namespace.strip("/")
    return f"{ns}/" if ns else ""


def _overriding():
    """QoS overriding options of every topic: ROS 2's ``qos_overrides.<topic>.publisher|subscription.
    <policy>`` parameters (history, depth, reliability, durability) override the defaults."""
    from rclpy.qos import QoSPolicyKind
    from rclpy.qos_overriding_options import QoSOverridingOptions

    return QoSOverridingOptions([getattr(QoSPolicyKind, k) for k in _OVERRIDABLE])


def _managed_node(twin: TwinNode, node_name: str, context):
    """An ``rclpy.lifecycle.LifecycleNode`` whose transitions call the twin's ``_on_*`` methods."""
    from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn

    ok, failure = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE

    class ManagedTwin(LifecycleNode):
        def on_configure(self, state):
            return ok if twin._on_configure() else failure

        def on_activate(self, state):
            twin._on_activate()
            return super().on_activate(state)

        def on_deactivate(self, state):
            twin._on_deactivate()
            return super().on_deactivate(state)

        def on_cleanup(self, state):
            twin._on_cleanup()
            return super().on_cleanup(state)

        def on_shutdown(self, state):
            twin.shutdown_requested = True    # spin() ends, closes the recording, writes the summary
            return super().on_shutdown(state)

        def on_error(self, state):
            if twin.configured:
                twin._on_cleanup()
            return ok                         # back to unconfigured

    return ManagedTwin(node_name, context=context)


class _Services:
    """``~/reset``, ``~/pause``, ``~/resume`` (``std_srvs/srv/Trigger``) and ``~/step``
    (``flexmb_msgs/srv/Step``), served on the executor thread. A call the node's state does not
    allow answers ``success: false`` and says why."""

    def __init__(self, twin: TwinNode):
        self.twin = twin
        self.names = {}
        try:
            from std_srvs.srv import Trigger
        except ModuleNotFoundError:
            twin.log.warning("std_srvs is not installed (pip install ros-std-srvs): no ~/reset, ~/pause, ~/resume")
        else:
            for name, cb in (("~/reset", self.reset), ("~/pause", self.pause), ("~/resume", self.resume)):
                self._serve(Trigger, name, cb)
        try:
            from flexmb_msgs.srv import Step
        except ImportError:
            twin.log.warning("flexmb_msgs has no srv/Step (rebuild it: make setup): no ~/step")
        else:
            self._serve(Step, "~/step", self.step)

    def _serve(self, srv_type, name: str, cb) -> None:
        self.names[name] = self.twin.node.resolve_service_name(name)
        self.twin.node.create_service(srv_type, name, lambda req, resp, _n=name: self._call(_n, cb, req, resp),
                                      qos_profile=_service_qos())

    def _call(self, name: str, cb, request, response):
        why = cb(request, response)
        response.success = why is None or why.startswith("ok:")
        response.message = why[3:] if why and why.startswith("ok:") else why or "ok"
        if not response.success:
            self.twin.log.warning(f"{self.names[name]}: refused: {response.message}")
        return response

    def _state(self) -> str:
        t = self.twin
        return "active" if t.active else ("inactive" if t.configured else "unconfigured")

    def _need(self, active: bool) -> str | None:
        t = self.twin
        if not t.configured or (active and not t.active):
            return (f"the node is {self._state()} (lifecycle); "
                    f"{'configure and activate' if not t.configured else 'activate'} it first")
        return None

    def reset(self, request, response) -> str | None:
        t = self.twin
        why = self._need(active=False)
        if why:
            return why
        if t.recorder is not None:
            return ("the node records to '" + t.p.record[:80] + "': a recording's time cannot go back; "
                    "reset is refused while recording")
        t.stepper.reset()
        t._accepted_wall = 0.0
        return f"ok:reset to the initial state at t = {t.runner.t:g} s"

    def pause(self, request, response) -> str | None:
        t = self.twin
        why = self._need(active=True)
        if why:
            return why
        t.paused = True
        t.stepper.hold()
        return f"ok:paused at t = {t.runner.t:.9g} s (commands are still applied; ~/step advances, ~/resume runs)"

    def resume(self, request, response) -> str | None:
        t = self.twin
        why = self._need(active=True)
        if why:
            return why
        t.paused = False
        t.stepper.release()
        return f"ok:running from t = {t.runner.t:.9g} s"

    def step(self, request, response) -> str | None:
        t = self.twin
        response.sim_time = t.runner.t if t.runner is not None else 0.0
        why = self._need(active=True)
        if why:
            return why
        if t.p.mode == "realtime" and not t.paused:
            return "the twin runs in realtime (it steps on the wall clock); call ~/pause first"
        n = int(request.steps)
        if not 1 <= n <= MAX_STEP_SERVICE:
            return f"steps: expected 1 to {MAX_STEP_SERVICE}, got {n}"
        done, message = t.stepper.step_n(n)
        response.steps_done = done
        response.sim_time = t.runner.t
        if done < n:
            return f"{done} of {n} steps advanced, t = {t.runner.t:.9g} s: {message}"
        return f"ok:{n} steps, t = {t.runner.t:.9g} s"


def _service_qos():
    from rclpy.qos import qos_profile_services_default

    return qos_profile_services_default
