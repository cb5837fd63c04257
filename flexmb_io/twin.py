"""The twin without ROS: a :class:`Simulator` stepped on external commands, reporting samples.

The live node, ``flexmb run --mcap`` and ``flexmb replay`` all step through :class:`TwinRunner`,
so a lockstep node run and an offline replay of its recorded commands are the same computation.

Command timing, the one rule everything relies on: a command accepted while the twin is at
simulated time ``t_n`` takes effect on the step ``t_n → t_n + Δt``, whose actuator lengths are
the command schedule evaluated at ``t_n + Δt``. A recording stores each command with log time
``t_n`` (ns of simulated time), so a replay re-applies it before the same step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexmb_core.errors import ConvergenceError, FlexmbError
from flexmb_core.faults import FaultMonitor
from flexmb_core.model.model import Model
from flexmb_core.observers import actuator_forces
from flexmb_core.report import TwinReporter, TwinSample
from flexmb_core.scene.schema import SolverSpec
from flexmb_core.simulator import Simulator

from .commands import HOLDS, SIZE, CommandSchedule, Rejection
from .messages import stamp_seconds
from .shells import ShellShapes

_NO_FORCES = np.zeros(0)


@dataclass
class RunnerOptions:
    """How the twin treats its inputs (the node's parameters of the same names)."""

    command_source: str = "external"      # external (topics) | scene (the scene's own commands)
    command_timeout: float = 0.5          # s of simulated time; inf disables
    timeout_behaviour: str = "hold"       # hold | ramp_to_rest
    ramp_time: float = 2.0                # s
    stale_after: float = 1.0              # s
    max_lead: float = 1.0                 # s
    command_hold: str = "smooth"          # smooth (C¹) | ramp (linear) | step: see flexmb_io.commands
    max_command_rate: float = 10.0        # m/s, commanded rates beyond are rejected (actuators without a servo)
    max_command_accel: float = 50.0       # m/s², most acceleration of a smooth hold's join (CommandSchedule)
    max_trajectory_points: int = 10000    # longer trajectories are rejected
    # JointState commands (~/joint_commands): False applies them on arrival (their stamp ignored, as
    # topic_based_ros2_control stamps with its controller manager's clock); True checks and uses the
    # stamp like an ActuatorCommand's
    joint_command_stamps: bool = False

    @classmethod
    def from_params(cls, p) -> "RunnerOptions":
        """The options of a node's :class:`~ros2_node.params.NodeParams` (same names; the timeout
        behaviour is ``command_timeout_behaviour`` there)."""
        return cls(command_source=p.command_source, command_timeout=p.command_timeout,
                   timeout_behaviour=p.command_timeout_behaviour, ramp_time=p.ramp_time, stale_after=p.stale_after,
                   max_lead=p.max_lead, command_hold=p.command_hold, max_command_rate=p.max_command_rate,
                   max_command_accel=p.max_command_accel, max_trajectory_points=p.max_trajectory_points, joint_command_stamps=p.joint_command_stamps)

    def validate(self) -> None:
        if self.command_source not in ("external", "scene"):
            raise FlexmbError(f"command_source must be 'external' or 'scene', got {self.command_source!r}")
        if self.timeout_behaviour not in ("hold", "ramp_to_rest"):
            raise FlexmbError(f"command_timeout_behaviour must be 'hold' or 'ramp_to_rest', got "
                              f"{self.timeout_behaviour!r}")
        if self.command_hold not in HOLDS:
            raise FlexmbError(f"command_hold must be one of {list(HOLDS)}, got {self.command_hold!r}")
        for name in ("command_timeout", "ramp_time", "stale_after", "max_lead", "max_command_rate",
                     "max_command_accel"):
            v = getattr(self, name)
            if not (v > 0):
                raise FlexmbError(f"{name} must be > 0, got {v}")
        if not (self.max_trajectory_points >= 1 and float(self.max_trajectory_points).is_integer()):
            raise FlexmbError(f"max_trajectory_points must be an integer ≥ 1, got {self.max_trajectory_points!r}")


@dataclass
class StepOutcome:
    """What one :meth:`TwinRunner.step` did (read the state with :meth:`TwinRunner.sample`)."""

    advanced: bool                 # False: the step failed and the state was kept
    converged: bool
    message: str = ""


# failed steps in a row after which the twin stops (TwinRunner)
STUCK_AFTER = 10


@dataclass
class RunnerCounters:
    steps: int = 0                 # steps attempted
    failed_steps: int = 0          # steps rejected (no convergence, or a non-finite state)
    flagged_steps: int = 0         # steps accepted unconverged (policy accept_flagged)
    substepped_steps: int = 0
    failed_in_a_row: int = 0       # failed steps since the last one that advanced
    last_message: str = ""
    rejections: dict = field(default_factory=dict)   # kind → count
    faults: dict = field(default_factory=dict)       # flexmb_core.faults kind → steps that showed it
    stopped: str = ""              # why the twin stopped stepping (limits.on_violation: stop), "" if it did not


class TwinRunner:
    """Steps one compiled model on external (or scene) commands and reports :class:`TwinSample`.

    Never raises on a bad step: a step that does not converge (after the scene's
    ``on_unconverged`` policy) or leaves a non-finite state is rolled back and reported in the
    outcome; the next call tries again from the last good state with the commands then in force.
    After :data:`STUCK_AFTER` failed steps in a row the twin stops (``counters.stopped``, as
    ``limits.on_violation: stop`` does) and says why: a state from which no step converges does not
    recover by itself, and each try costs the most the solver spends on a step (measured, issue 12:
    a frame-leg twin whose commands had kinked by 1.5 cm in one step failed every step from
    t = 3.211 s on, with 16 sub-steps each, its time stopped for good and the node busy).
    """

    def __init__(self, model: Model, spec: SolverSpec | None = None, options: RunnerOptions | None = None):
        self.model = model
        self.options = options or RunnerOptions()
        self.options.validate()
        self.sim = Simulator(model, spec)
        if self.sim.spec.analysis != "dynamic":
            raise FlexmbError(f"scene '{model.scene.name}': the twin steps dynamics; solver.analysis is "
                              f"'{self.sim.spec.analysis}'")
        self.dt = float(self.sim.spec.dt)
        self.reporter = TwinReporter(model)
        self.faults = FaultMonitor(model)
        self.counters = RunnerCounters()
        self.schedule: CommandSchedule | None = None
        self._backup = None
        self._member_kinds = tuple(m.kind for m in model.members)
        # the sample (flexmb_core.report) carries the members; the shells' nodes are gathered here,
        # at the same state, for ~/shape and the rerun view
        self.shells = ShellShapes(model)

    @property
    def member_kinds(self) -> tuple[str, ...]:
        return self._member_kinds

    @property
    def t(self) -> float:
        return float(self.sim.state.t)

    def start(self, warmup: bool = True) -> TwinSample:
        """Compile/load the kernels, set up the initial state (the scene's ``initial_state``)."""
        if warmup:
            self.sim.warmup()
        act = self.model.actuators
        rest = self.sim.command_lengths(self.sim.state.t)
        if self.options.command_source == "external" and act.l0.size:
            o = self.options
            # commanded rates are limited by the servo where the scene declares one
            max_rate = np.full(act.l0.size, float(o.max_command_rate))
            if act.servo is not None:
                max_rate[act.servo.index] = act.servo.max_rate
            self.schedule = CommandSchedule(act.names, act.stroke, rest, timeout=o.command_timeout,
                                            behaviour=o.timeout_behaviour, ramp_time=o.ramp_time,
                                            stale_after=o.stale_after, max_lead=o.max_lead, hold=o.command_hold,
                                            dt=self.dt, max_rate=max_rate,
                                            max_points=int(o.max_trajectory_points),
                                            max_accel=float(o.max_command_accel))
            self.sim.set_commands(rest)
        if warmup and self.schedule is not None:
            self.schedule.warmup()
        if warmup and self.faults.active:
            self.faults.check(self.sim.state.q, np.zeros(0))      # compile the limits' kernels now
        self.sim.initialize()
        self._backup = self.sim.data.copy()
        return self.sample()

    def reset(self) -> TwinSample:
        """Back to the initial state, as :meth:`start` left it (``t`` = 0, the scene's
        ``initial_state``, the commands at their start lengths, the counters at zero): a fresh
        :class:`Simulator` of the same model and solver settings (its kernels are compiled already,
        so no warm-up), so that the steps after a reset repeat the steps after the start bit for bit."""
        self.sim = Simulator(self.model, self.sim.spec)
        self.counters = RunnerCounters()
        self.schedule = None
        return self.start(warmup=False)

    # -- inputs (return None when accepted) ----------------------------------------------------
    def _count(self, r: Rejection | None) -> Rejection | None:
        if r is not None:
            self.counters.rejections[r.kind] = self.counters.rejections.get(r.kind, 0) + 1
        return r

    def _need_schedule(self, topic: str) -> CommandSchedule:
        if self.schedule is None:
            why = ("the scene has no actuators" if not self.model.actuators.l0.size
                   else "command_source is 'scene'")
            raise FlexmbError(f"{topic}: this twin takes no external commands ({why})")
        return self.schedule

    def command_array(self, topic: str, values, arrival: float | None = None) -> Rejection | None:
        """Lengths in scene order, applied now; ``arrival`` (s): the twin time the command arrived
        at on the wall clock (:meth:`flexmb_io.commands.CommandSchedule.command_array`), None: now."""
        return self._count(self._need_schedule(topic).command_array(topic, values, self.t, arrival))

    def command_named(self, topic: str, names, lengths, velocities=None, stamp: float = 0.0,
                      arrival: float | None = None) -> Rejection | None:
        return self._count(self._need_schedule(topic).command_named(topic, names, lengths, velocities, stamp, self.t,
                                                                    arrival))

    def command_trajectory(self, topic: str, names, stamp: float, points) -> Rejection | None:
        return self._count(self._need_schedule(topic).command_trajectory(topic, names, stamp, points, self.t))

    def command_joint_state(self, topic: str, names, positions, velocities, efforts,
                            stamp: float = 0.0, arrival: float | None = None) -> Rejection | None:
        """A ``sensor_msgs/JointState`` command (the ``topic_based_ros2_control`` convention):
        ``names`` some actuators in any order, ``positions (k,)`` their lengths (m), ``velocities``
        empty or ``(k,)`` rates (m/s); efforts must be empty (the actuators are length-controlled)."""
        schedule = self._need_schedule(topic)
        if len(efforts):
            return self._count(schedule._reject(Rejection(
                topic, SIZE, f"effort has {len(efforts)} values; the twin's actuators take position (length, m) "
                "commands, optionally with velocity (m/s), so effort must be empty")))
        if len(names) and not len(positions):
            return self._count(schedule._reject(Rejection(
                topic, SIZE, f"{len(names)} names but no position; the twin's actuators take position (length, m) "
                "commands — a velocity-only command is not supported")))
        return self.command_named(topic, names, positions, velocities, stamp, arrival)

    @property
    def rejected_commands(self) -> int:
        return sum(self.counters.rejections.values())

    @property
    def newest_command_stamp(self) -> float:
        return self.schedule.newest_stamp if self.schedule is not None else 0.0

    # -- stepping ------------------------------------------------------------------------------
    def step(self) -> StepOutcome:
        """Advance one Δt on the commands in force (see the module's timing rule)."""
        sim, c = self.sim, self.counters
        if c.stopped:
            return StepOutcome(False, True, c.stopped)
        c.steps += 1
        t_new = sim.state.t + self.dt
        outcome = self._attempt(t_new)
        if outcome is not None:
            if outcome.advanced:
                c.failed_in_a_row = 0
            return outcome
        c.failed_steps += 1
        c.failed_in_a_row += 1
        if c.failed_in_a_row >= STUCK_AFTER:
            c.stopped = (f"stopped at t = {sim.state.t:.6g} s: {c.failed_in_a_row} steps in a row failed, the last: "
                         f"{c.last_message} — no step converges from this state (~/reset restarts the twin)")
            c.last_message = c.stopped
        return StepOutcome(False, False, c.last_message)

    def _attempt(self, t_new: float) -> StepOutcome | None:
        """One try of the step to ``t_new`` on the commands in force: its outcome, or None when it
        failed (rolled back; the reason in ``counters.last_message``)."""
        sim, c = self.sim, self.counters
        if self.schedule is not None:
            sim.set_commands(self.schedule.lengths_at(t_new), check=False)   # validated on reception
        self._backup.assign(sim.data)
        message = ""
        try:
            res = sim.step(self.dt)
            converged = bool(res.converged)
            if not converged:
                c.flagged_steps += 1
                message = f"step to t = {t_new:.6g} s accepted unconverged: {res.message}"
            elif res.substeps > 1:
                c.substepped_steps += 1
                message = res.message
        except ConvergenceError as exc:
            sim.data.assign(self._backup)
            c.last_message = f"step to t = {t_new:.6g} s rejected, state kept at t = {sim.state.t:.6g} s: {exc}"
            return None
        st = sim.state
        if not (np.isfinite(st.q).all() and np.isfinite(st.v).all()):
            sim.data.assign(self._backup)
            c.last_message = f"step to t = {t_new:.6g} s produced non-finite values; state kept at t = {sim.state.t:.6g} s"
            return None
        if self.faults.active:
            fault = self._check_faults(t_new)
            if fault is not None:
                return fault
        if message:
            c.last_message = message
        return StepOutcome(True, converged, message)

    def _check_faults(self, t_new: float) -> StepOutcome | None:
        """The scene's ``limits:`` on the new state (flexmb_core.faults): None when all is well;
        else the outcome to report — stepping on (``report``) or rolled back and stopped (``stop``)."""
        sim, c = self.sim, self.counters
        forces = actuator_forces(self.model, sim.ws, sim.state) if self.faults.max_force < math.inf else _NO_FORCES
        found = self.faults.check(sim.state.q, forces)
        if not found:
            return None
        for f in found:
            c.faults[f.kind] = c.faults.get(f.kind, 0) + 1
        text = "; ".join(f.detail for f in found)
        if self.faults.stop:
            sim.data.assign(self._backup)
            c.stopped = (f"stopped at t = {sim.state.t:.6g} s (limits.on_violation: stop) — the step to "
                         f"t = {t_new:.6g} s was rolled back: {text}")
            c.last_message = c.stopped
            return StepOutcome(False, True, c.stopped)
        c.last_message = f"limits violated at t = {t_new:.6g} s: {text}"
        return StepOutcome(True, True, c.last_message)

    def sample(self, full: bool = True) -> TwinSample:
        """The current state as a :class:`TwinSample` (the same object every call); see
        :meth:`TwinReporter.read` for ``full``. A full sample also refreshes :attr:`shells`."""
        s = self.reporter.read(self.sim, full)
        if full:
            self.shells.read(self.sim.state.q)
        return s


def apply_message(runner: TwinRunner, topic_kind: str, topic: str, msg,
                  arrival: float | None = None) -> Rejection | None:
    """Feed one decoded command message (rclpy or :mod:`flexmb_io.wire` message, or dict) to the runner.

    ``topic_kind`` is ``commands`` (Float64MultiArray), ``actuator_commands`` (ActuatorCommand),
    ``joint_trajectory`` (JointTrajectory) or ``joint_commands`` (JointState: the stamp counts only
    with the runner option ``joint_command_stamps``, else the command applies on arrival).
    ``arrival`` (s): the twin time an unstamped command arrived at on the wall clock (a realtime
    node's mapping, recorded as the command's publish time); None: the runner's time.
    """
    def get(m, k):                # dicts, rclpy messages and flexmb_io.wire messages, mixed at any level
        return m[k] if isinstance(m, dict) else getattr(m, k)
    if topic_kind == "commands":
        return runner.command_array(topic, list(get(msg, "data")), arrival)
    if topic_kind == "actuator_commands":
        st = get(get(msg, "header"), "stamp")
        return runner.command_named(topic, list(get(msg, "names")), list(get(msg, "lengths")),
                                    list(get(msg, "velocities")), stamp_seconds(st), arrival)
    if topic_kind == "joint_trajectory":
        st = get(get(msg, "header"), "stamp")
        raw = get(msg, "points")
        limit = runner.options.max_trajectory_points
        # beyond the limit the schedule rejects on the count alone: do not convert a huge message
        pts = raw if len(raw) > limit else [(stamp_seconds(get(p, "time_from_start")), get(p, "positions"),
                                             get(p, "velocities")) for p in raw]
        return runner.command_trajectory(topic, list(get(msg, "joint_names")),
                                         stamp_seconds(st), pts)
    if topic_kind == "joint_commands":
        stamp = stamp_seconds(get(get(msg, "header"), "stamp")) if runner.options.joint_command_stamps else 0.0
        return runner.command_joint_state(topic, list(get(msg, "name")), list(get(msg, "position")),
                                          list(get(msg, "velocity")), list(get(msg, "effort")), stamp, arrival)
    raise ValueError(f"unknown command topic kind {topic_kind!r}")
