"""``flexmb play``: a controller stand-in that streams actuator commands to a twin node over DDS.

Sources: the scene's own command definition (signals or a program such as the Stewart appendix
law: ``flexmb play SCENE``) or a CSV table (``--csv``: ``t, L1..Ln[, rate1..raten]``, linear
interpolation). Forms: ``flexmb_msgs/ActuatorCommand`` (default: named, stamped with the time the
lengths are meant for, with rates) or ``std_msgs/Float64MultiArray`` (``--topic commands``).

The command law's time starts at the twin's time when playback begins (a realtime twin may have
been holding its start lengths for a while): no jump from rest, whenever the player starts.

Pacing. ``lockstep``: send the command for ``t + Δt``, wait for the twin's status that answers it,
repeat (deterministic). ``realtime``: send at ``--rate`` Hz on the wall clock, for the twin's time
estimated from its ``/clock`` (the twin owns time). Either way the player measures the end-to-end
command→state latency (until the first ``TwinStatus`` whose ``command_stamp`` is its stamp or a
newer one: the twin echoes the newest command a state includes) and, when the command program
knows the commanded pose, how closely ``~/platform_pose`` tracks it.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from flexmb_core.errors import FlexmbError
from flexmb_core.tracking import pose_errors
from flexmb_io import messages as M
from flexmb_io import topics as T
from flexmb_io.realtime import Series
from flexmb_io.wire import serialize

from .convert import message_class
from .taking import take_waiting

UNANSWERED_AFTER = 10.0     # s after which a command without an answer is counted unanswered and forgotten


# s ahead of its estimate of the twin's time that the realtime player stamps its commands for, as
# a controller with a short planning horizon does: a twin joins a command stamped ahead at its
# stamp, exactly on the law, while one stamped behind is a line extrapolated from the past.
# Measured (issue 12, a node recording of the 1-element frame-leg twin on a loaded machine, its
# commands replayed offline): the player's stamps were 14 ms behind the twin's time (p50; 90 ms at
# p1), and the twin took 3.0 Newton iterations per step, commanded accelerations up to 45 m/s²;
# the same commands stamped 100 ms later, 1.7 iterations, 2.6 m/s²
DEFAULT_LEAD = 0.05


class TwinClock:
    """The realtime player's estimate of the twin's time: the wall clock, slewed toward the twin's
    reports.

    Reports (``/clock``, statuses) come late, never early, so one that shows the twin further on
    than the estimate is taken at once; one that shows it behind pulls the estimate back by at most
    ``slew`` s per s of wall time (a twin slower than real time is followed, down to RTF 1 −
    slew), or at once beyond ``resync`` s (a paused or reset twin). Between reports the estimate
    runs with the wall clock. Measured (issue 12): the estimate it replaces froze three steps after
    the newest report; when the node's reports lagged (up to 0.6 s under load) the player's stamps
    stopped, then jumped by up to 0.5 s, and the twin took the lines of a curved motion far from
    their stamps — 1.5 cm kinks in one step, Newton iterations from 1.2 to 11 per step, and a twin
    that stalled. An estimate that errs ahead is harmless: a line stamped ahead is joined at its
    stamp (:class:`flexmb_io.commands.CommandSchedule`)."""

    def __init__(self, slew: float = 0.25, resync: float = 0.2):
        self.slew, self.resync = slew, resync
        self._t = math.nan          # s of twin time at the wall time _wall
        self._wall = 0.0

    @property
    def started(self) -> bool:
        return math.isfinite(self._t)

    def now(self, wall: float) -> float:
        """The estimated twin time (s) at ``wall`` (perf_counter s)."""
        return self._t + (wall - self._wall)

    def report(self, t: float, wall: float) -> None:
        """The twin reported time ``t`` (s); received at ``wall``."""
        if not self.started:
            self._t, self._wall = t, wall
            return
        est = self.now(wall)
        err = t - est
        if err < 0.0 and err > -self.resync:
            err = max(err, -self.slew * (wall - self._wall))
        self._t, self._wall = est + err, wall


class CommandSource:
    """Commanded lengths (m) and rates (m/s) as functions of time."""

    def __init__(self, names, fn, reference_poses=None):
        self.names = list(names)
        self._fn = fn
        # times (n,) s → commanded centroids (n, 3) m and orientations (n, 4) (w, x, y, z); None: no
        # pose law to track against
        self.reference_poses = reference_poses

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        h = 1e-4
        lengths = self._fn(t)
        rates = (self._fn(t + h) - self._fn(max(t - h, 0.0))) / (t + h - max(t - h, 0.0))
        return lengths, rates

    @classmethod
    def from_scene(cls, path: str) -> "CommandSource":
        from flexmb_core.model.compile import compile_scene
        from flexmb_core.scene import load_scene
        from flexmb_core.simulator import Simulator

        model = compile_scene(load_scene(path))
        if not model.actuators.l0.size:
            raise FlexmbError(f"{path}: the scene has no actuators to command")
        sim = Simulator(model)
        program = model.program
        ref = program.reference_poses if hasattr(program, "reference_poses") else None
        return cls(model.actuators.names, lambda t: sim.command_lengths(t), ref)

    @classmethod
    def from_csv(cls, path: str, names: list[str]) -> "CommandSource":
        try:
            data = np.loadtxt(path, delimiter=",", comments="#", ndmin=2, skiprows=_header_rows(path))
        except (OSError, ValueError) as exc:
            raise FlexmbError(f"{path}: cannot read the command table: {exc}") from None
        n = len(names)
        if any(not x for x in names) or len(set(names)) != n:
            raise FlexmbError(f"--names {','.join(names)[:120]!r}: expected distinct, non-empty actuator names")
        if not np.all(np.isfinite(data)):
            row = int(np.argwhere(~np.isfinite(data))[0, 0])
            raise FlexmbError(f"{path}: data row {row + 1} of the table holds a value that is not a finite number "
                              f"({np.array2string(data[row][:7], precision=6)[:120]})")
        if data.shape[1] not in (1 + n, 1 + 2 * n):
            raise FlexmbError(f"{path}: expected columns t, {n} lengths[, {n} rates], got {data.shape[1]} columns")
        if not np.all(np.diff(data[:, 0]) > 0):
            raise FlexmbError(f"{path}: the time column must increase strictly")
        return cls(names, TableLookup(data[:, 0], data[:, 1:1 + n]))


class TableLookup:
    """Piecewise-linear lookup in a command table, O(1) per call, vectorized over the columns.

    Equals ``np.interp(t, times, values[:, i])`` for every column (held beyond the ends). A
    player asks for times that mostly increase by one step, so a cursor on the current interval
    moves by at most a few rows per call; a jump far away (backwards or ahead) is re-located by
    bisection. ``np.interp`` over the whole table per column cost 1 ms per command on the 20 s
    table of ``flexmb commands stewart`` — more than a 1 kHz player's period.

    Parameters
    ----------
    times : (m,) s, strictly increasing
    values : (m, n) the columns to interpolate
    """

    _SCAN = 8          # rows walked before falling back to bisection

    def __init__(self, times: np.ndarray, values: np.ndarray):
        self.t = np.ascontiguousarray(times, dtype=float)
        self.v = np.ascontiguousarray(values, dtype=float)
        self.j = 0                     # the current interval [t[j], t[j+1]]
        self._out = np.empty(self.v.shape[1])

    def __call__(self, tt: float) -> np.ndarray:
        t, v, m = self.t, self.v, self.t.size
        if tt <= t[0] or m == 1:
            return v[0].copy()
        if tt >= t[-1]:
            return v[-1].copy()
        j = self.j
        for _ in range(self._SCAN):
            if tt < t[j]:
                j -= 1
            elif tt >= t[j + 1]:
                j += 1
            else:
                break
        else:
            j = int(np.searchsorted(t, tt, side="right")) - 1
        self.j = j
        # np.interp's formula, so the values are the same to the last bit
        out = np.subtract(v[j + 1], v[j], out=self._out)
        out /= t[j + 1] - t[j]
        out *= tt - t[j]
        out += v[j]
        return out.copy()


def _header_rows(path: str) -> int:
    with open(path) as f:
        first = f.readline()
    try:
        [float(x) for x in first.split(",")]
        return 0
    except ValueError:
        return 1


class Player:
    """Streams one :class:`CommandSource` to the twin named ``twin`` and measures what comes back."""

    def __init__(self, source: CommandSource, *, context, twin: str = T.DEFAULT_NODE_NAME, mode: str = "lockstep",
                 until: float = 20.0, dt: float = 1e-3, rate: float = 1000.0, topic: str = "actuator_commands",
                 qos_depth: int = 100, timeout: float = 30.0, lead: float = DEFAULT_LEAD):
        import rclpy
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        if mode not in ("lockstep", "realtime"):
            raise FlexmbError(f"--mode: expected lockstep or realtime, got {mode!r}")
        self.source, self.mode, self.until, self.dt, self.rate = source, mode, until, dt, rate
        self.timeout = timeout
        if not (lead >= 0.0 and math.isfinite(lead)):
            raise FlexmbError(f"--lead: expected s ≥ 0, got {lead!r}")
        self.lead = lead
        self.context = context
        self.node = rclpy.create_node("flexmb_player", context=context)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=qos_depth, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        self.topic = {"actuator_commands": T.ACTUATOR_COMMANDS, "commands": T.COMMANDS}.get(topic)
        if self.topic is None:
            raise FlexmbError(f"--topic: expected actuator_commands or commands, got {topic!r}")
        self.pub = self.node.create_publisher(message_class(self.topic.type), self.topic.resolved(twin), qos)
        self._status_sub = self.node.create_subscription(message_class(T.STATUS.type), T.STATUS.resolved(twin),
                                                         self._on_status, qos)
        self.node.create_subscription(message_class(T.PLATFORM_POSE.type), T.PLATFORM_POSE.resolved(twin),
                                      self._on_pose, qos)
        self.node.create_subscription(message_class(T.CLOCK.type), T.CLOCK.resolved(twin), self._on_clock, qos)
        try:
            from rclpy.experimental import EventsExecutor
            self.executor = EventsExecutor(context=context)
        except Exception:          # pragma: no cover
            from rclpy.executors import SingleThreadedExecutor
            self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.sim_time = None                  # twin's newest reported time (s)
        self.t0 = 0.0                         # twin's time when playback began: the law's t = 0
        self.clock = TwinClock()              # realtime: the twin's time estimated between reports
        self.sent: dict[int, float] = {}      # stamp (ns) → wall time sent, in sending order, until answered or expired
        self.expired = 0                      # commands unanswered for UNANSWERED_AFTER s (dropped from sent)
        self._next_expiry = 0.0               # perf_counter of the next sweep of sent (once a second)
        self.latencies = Series()             # s, command sent → first status echoing its stamp or a newer one
        self.answered_ns = -1
        # the twin's platform poses, rows (t s, x y z m, qw qx qy qz), compared with the law at the end
        self.poses = Series(width=8)
        self.statuses = 0
        self.unconverged = 0
        self.last_status = None

    # -- callbacks ------------------------------------------------------------------------------
    def _on_status(self, msg) -> None:
        """A status (one per command the twin answered): read it, then the others already waiting,
        so that a player slower than the answers (an overloaded machine) leaves the executor's
        queue no entries to keep (``ros2_node/taking.py``)."""
        self._read_status(msg, time.perf_counter())
        for waiting in take_waiting(self._status_sub):
            self._read_status(waiting, time.perf_counter())

    def _read_status(self, msg, now: float) -> None:
        self.statuses += 1
        self.last_status = msg
        if not msg.converged:
            self.unconverged += 1
        ns = msg.command_stamp.sec * 1_000_000_000 + msg.command_stamp.nanosec
        # the state includes every command stamped up to the one it echoes: a twin that took two
        # commands before one step echoes only the newer, and the older one's latency counts too
        # (sent in stamp order; an out-of-order one waits for its own echo or expires)
        sent = self.sent
        while sent:
            first = next(iter(sent))
            if first > ns:
                break
            self.latencies.add(now - sent.pop(first))
        if ns in sent:
            self.latencies.add(now - sent.pop(ns))
        self.answered_ns = max(self.answered_ns, ns)
        self._note_time(msg.sim_time, now)

    def _on_clock(self, msg) -> None:
        self._note_time(M.stamp_seconds(msg.clock), time.perf_counter())

    def _note_time(self, t: float, wall: float) -> None:
        if self.sim_time is None or t > self.sim_time:
            self.sim_time = t
        self.clock.report(t, wall)      # every report: a paused or reset twin pulls the estimate back

    def _on_pose(self, msg) -> None:
        """A platform pose: kept, and compared with the commanded law once the run is over
        (:meth:`tracking`). Evaluating the law here cost ~0.13 ms per pose on this executor's
        thread, where a status that arrived meanwhile waited — the latency being measured."""
        if self.source.reference_poses is None:
            return
        t = M.stamp_seconds(msg.header.stamp) - self.t0
        if t < 0.0 or t > self.until:
            return                           # before playback the twin holds its start pose, after it
            #                                  it stops (command timeout): the law is not played there
        p, o = msg.pose.position, msg.pose.orientation
        self.poses.add((t, p.x, p.y, p.z, o.w, o.x, o.y, o.z))

    def tracking(self) -> dict | None:
        """The twin's platform poses against the commanded law (None without poses or a law):
        max and rms centroid distance (m), max orientation angle (rad), samples."""
        rows = self.poses.values
        if self.source.reference_poses is None or not len(rows):
            return None
        pos, ang = pose_errors(rows[:, 1:4], rows[:, 4:8], *self.source.reference_poses(rows[:, 0]))
        return {"max_position_error_m": float(pos.max()),
                "rms_position_error_m": float(np.sqrt(np.mean(np.square(pos)))),
                "max_orientation_error_rad": float(ang.max()), "samples": int(pos.size)}

    # -- sending ---------------------------------------------------------------------------------
    def _send(self, t_target: float) -> None:
        # the command law starts at the twin's time when playback began (t0), from rest
        lengths, rates = self.source.at(t_target - self.t0)
        ns = int(round(t_target * 1e9))
        if self.topic is T.COMMANDS:
            d = M.float64_array(lengths)
        else:
            d = M.actuator_command(t_target, self.source.names, lengths, rates)
            now = time.perf_counter()
            self.sent[ns] = now
            if now >= self._next_expiry:
                self._next_expiry = now + 1.0
                self._expire(now)
        self.pub.publish(serialize(self.topic.type, d))

    def _expire(self, now: float) -> None:
        """Forget commands unanswered for :data:`UNANSWERED_AFTER` s (counted as unanswered): a twin
        that drops commands must not grow the client's memory for as long as it runs."""
        old = [ns for ns, sent in self.sent.items() if now - sent > UNANSWERED_AFTER]
        for ns in old:
            del self.sent[ns]
        self.expired += len(old)

    def _wait_for_twin(self) -> None:
        t_end = time.monotonic() + self.timeout
        while self.sim_time is None and self.context.ok():
            if time.monotonic() > t_end:
                raise FlexmbError(f"no /clock or status from the twin within {self.timeout} s "
                                  "(is `flexmb node` running on this ROS_DOMAIN_ID?)")
            self.executor.spin_once(timeout_sec=0.05)
        # let discovery of the command topic settle before the first command
        t_end = time.monotonic() + self.timeout
        while self.pub.get_subscription_count() == 0 and self.context.ok():
            if time.monotonic() > t_end:
                raise FlexmbError(f"the twin does not subscribe to {self.pub.topic_name}")
            self.executor.spin_once(timeout_sec=0.05)

    def run(self) -> dict:
        self._wait_for_twin()
        self.t0 = self.sim_time
        t_start = time.perf_counter()
        if self.mode == "lockstep":
            self._run_lockstep()
        else:
            self._run_realtime()
        # let the last answers arrive
        t_end = time.monotonic() + 1.0
        while self.sent and time.monotonic() < t_end and self.context.ok():
            self.executor.spin_once(timeout_sec=0.02)
        return self.summary(time.perf_counter() - t_start)

    def _run_lockstep(self) -> None:
        t = self.sim_time
        n = int(round(self.until / self.dt))
        for k in range(1, n + 1):
            target = t + k * self.dt
            ns = int(round(target * 1e9))
            self._send(target)
            t_end = time.monotonic() + self.timeout
            if self.topic is T.COMMANDS:       # no stamp to match: wait for the twin's time to move on
                while self.context.ok() and (self.sim_time or 0.0) < target - 0.5 * self.dt:
                    if time.monotonic() > t_end:
                        raise FlexmbError(f"the twin did not answer the command for t = {target:.6f} s "
                                          f"within {self.timeout} s")
                    self.executor.spin_once(timeout_sec=0.01)
                continue
            while self.context.ok() and self.answered_ns < ns:
                if time.monotonic() > t_end:
                    raise FlexmbError(f"the twin did not answer the command for t = {target:.6f} s within "
                                      f"{self.timeout} s")
                self.executor.spin_once(timeout_sec=0.01)

    def _run_realtime(self) -> None:
        period = 1.0 / self.rate
        # stamped commands go out for a time ahead of the twin's (see DEFAULT_LEAD); bare lengths
        # apply on arrival, so they are sent for the twin's time
        lead = 0.0 if self.topic is T.COMMANDS else self.lead
        t0 = time.perf_counter()
        k = 0
        last = -1.0
        while self.context.ok():
            now = time.perf_counter()
            t_twin = self.clock.now(now)           # see TwinClock
            if t_twin - self.t0 >= self.until:
                break
            # the estimate may step back when a /clock arrives late: stamps must never decrease
            target = max(t_twin + self.dt + lead, last + 1e-6)
            self._send(target)
            last = target
            k += 1
            deadline = t0 + k * period
            while self.context.ok():
                rem = deadline - time.perf_counter()
                if rem <= 0:
                    break
                self.executor.spin_once(timeout_sec=rem)

    def summary(self, wall: float) -> dict:
        lat = self.latencies.values
        out = {"mode": self.mode, "topic": self.topic.name, "wall_time_s": wall, "t0_s": self.t0, "statuses": self.statuses,
               "unconverged_reported": self.unconverged, "commands_unanswered": len(self.sent) + self.expired,
               "latency_s": {"p50": float(np.percentile(lat, 50)) if lat.size else None,
                             "p99": float(np.percentile(lat, 99)) if lat.size else None,
                             "max": float(lat.max()) if lat.size else None, "count": int(lat.size)}}
        tracking = self.tracking()
        if tracking is not None:
            out["tracking"] = tracking
        s = self.last_status
        if s is not None:
            out["twin"] = {"sim_time_s": s.sim_time, "steps": int(s.steps), "deadline_misses": int(s.deadline_misses),
                           "unconverged_steps": int(s.unconverged_steps), "rejected_commands": int(s.rejected_commands),
                           "real_time_factor": s.real_time_factor}
        return out

    def close(self) -> None:
        try:
            self.executor.remove_node(self.node)
        except Exception:
            pass
        self.node.destroy_node()


def run_player(source: CommandSource, *, json_out: str | None = None, **kw) -> dict:
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(args=["flexmb_player"], context=context)
    player = None
    try:
        player = Player(source, context=context, **kw)
        summary = player.run()
    finally:
        if player is not None:
            player.close()
        if context.ok():
            rclpy.shutdown(context=context)
    if json_out:
        Path(json_out).parent.mkdir(parents=True, exist_ok=True)
        Path(json_out).write_text(json.dumps(summary, indent=2) + "\n")
    return summary
