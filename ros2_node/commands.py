"""External actuator commands: validation and evaluation in simulated time (no ROS).

Three input forms, one per topic of the node (see :mod:`ros2_node.topics`):

- an array of lengths in scene order (``Float64MultiArray``: no stamp, applies from reception);
- named lengths with optional rates, stamped (``ActuatorCommand``): between commands the length
  follows ``L + v (t − stamp)`` (first-order hold), zero-order hold without rates;
- a trajectory (``JointTrajectory``): points at ``stamp + time_from_start``, interpolated by cubic
  Hermite when every point has velocities, linearly otherwise; it starts from the length in force
  when it arrives and holds its last point.

A message is accepted whole or rejected whole, with a :class:`Rejection` that names the topic,
the offending value and what was expected. Commands that address only some actuators leave the
others on their current command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Rejection kinds (stable identifiers: tests and the status message use them)
SIZE, NOT_FINITE, STROKE, UNKNOWN_NAME, DUPLICATE_NAME, STALE, OUT_OF_ORDER, FUTURE, BAD_TRAJECTORY = (
    "size", "not_finite", "stroke", "unknown_name", "duplicate_name", "stale", "out_of_order", "future",
    "bad_trajectory")


@dataclass(frozen=True)
class Rejection:
    """Why a command message was ignored."""

    topic: str
    kind: str
    detail: str

    def __str__(self) -> str:
        return f"{self.topic}: rejected ({self.kind}): {self.detail}"


@dataclass
class _Trajectory:
    idx: np.ndarray          # (k,) actuator indices
    times: np.ndarray        # (m,) s, increasing, times[0] = acceptance time
    lengths: np.ndarray      # (m, k) m
    rates: np.ndarray | None  # (m, k) m/s, or None → linear

    def at(self, t: float) -> np.ndarray:
        ts = self.times
        if t <= ts[0]:
            return self.lengths[0]
        if t >= ts[-1]:
            return self.lengths[-1]
        j = int(np.searchsorted(ts, t, side="right")) - 1
        h = ts[j + 1] - ts[j]
        s = (t - ts[j]) / h
        l0, l1 = self.lengths[j], self.lengths[j + 1]
        if self.rates is None:
            return l0 + s * (l1 - l0)
        v0, v1 = self.rates[j], self.rates[j + 1]
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        return h00 * l0 + h10 * h * v0 + h01 * l1 + h11 * h * v1


class CommandSchedule:
    """The commanded actuator lengths as a function of simulated time.

    Parameters
    ----------
    names : actuator names, scene order (na,)
    stroke : (na, 2) admissible lengths (m), inclusive
    rest : (na,) lengths at start (m): held until the first command, target of ``ramp_to_rest``
    timeout : s of simulated time without a command after which the timeout behaviour starts
        (``inf`` disables it; a running trajectory is never timed out)
    behaviour : ``hold`` (keep the last length, stop extrapolating) or ``ramp_to_rest``
    ramp_time : s, duration of the smooth ramp to ``rest``
    stale_after : s, stamped commands older than ``now − stale_after`` are rejected
    max_lead : s, stamped commands later than ``now + max_lead`` are rejected (clock mismatch)
    """

    def __init__(self, names, stroke: np.ndarray, rest: np.ndarray, *, timeout: float = math.inf,
                 behaviour: str = "hold", ramp_time: float = 1.0, stale_after: float = 1.0,
                 max_lead: float = 1.0):
        if behaviour not in ("hold", "ramp_to_rest"):
            raise ValueError(f"timeout behaviour must be 'hold' or 'ramp_to_rest', got {behaviour!r}")
        self.names = tuple(names)
        self.index = {n: i for i, n in enumerate(self.names)}
        self.stroke = np.asarray(stroke, dtype=float)
        # admissible lengths: the stroke, and always > 0 (an undeclared stroke is [0, inf])
        self._lo = np.maximum(self.stroke[:, 0], np.nextafter(0.0, 1.0))
        self._hi = self.stroke[:, 1].copy()
        self._all = np.arange(len(names))
        self.rest = np.asarray(rest, dtype=float).copy()
        self.timeout, self.behaviour, self.ramp_time = timeout, behaviour, ramp_time
        self.stale_after, self.max_lead = stale_after, max_lead
        na = len(self.names)
        self.base = self.rest.copy()         # length at the command's reference time
        self.rate = np.zeros(na)             # m/s
        self.t_ref = np.zeros(na)            # s, reference time of base (the stamp)
        self.trajectory: _Trajectory | None = None
        self.last_accept = -math.inf         # sim time of the newest accepted command
        self.last_stamp = -math.inf          # newest accepted stamp (ordering check)
        self.newest_stamp = 0.0              # stamp of the newest accepted command (0 for arrays)
        self._held: np.ndarray | None = None  # lengths frozen when the timeout started
        self._t_hold = 0.0
        self._out = np.zeros(na)
        self.accepted = 0
        self.rejected = 0

    # -- validation ----------------------------------------------------------------------------
    def _check_lengths(self, topic: str, names, values: np.ndarray, idx: np.ndarray | None = None) -> Rejection | None:
        """``values`` for actuators ``idx`` (all, in scene order, when None); NaN fails every comparison,
        so one vectorized test covers finiteness and the stroke, and messages are built on failure only."""
        lo = self._lo if idx is None else self._lo[idx]
        hi = self._hi if idx is None else self._hi[idx]
        ok = (values >= lo) & (values <= hi)
        if ok.all():
            return None
        if not np.all(np.isfinite(values)):
            bad = [f"{n}={v}" for n, v in zip(names, values) if not math.isfinite(v)]
            return Rejection(topic, NOT_FINITE, f"lengths must be finite, got {', '.join(bad)}")
        bad = [f"{n}={v:.6g} m (stroke [{a:.6g}, {b:.6g}] m)"
               for n, v, a, b, o in zip(names, values, lo, hi, ok) if not o]
        return Rejection(topic, STROKE, "lengths outside the actuator stroke: " + ", ".join(bad))

    def _check_names(self, topic: str, names) -> Rejection | None:
        unknown = [n for n in names if n not in self.index]
        if unknown:
            return Rejection(topic, UNKNOWN_NAME, f"unknown actuator names {unknown}; "
                             f"this twin has {list(self.names)}")
        if len(set(names)) != len(names):
            return Rejection(topic, DUPLICATE_NAME, f"actuator names repeated in {list(names)}")
        return None

    def _check_stamp(self, topic: str, stamp: float, now: float) -> Rejection | None:
        if stamp <= 0.0:
            return None
        if stamp < self.last_stamp:
            return Rejection(topic, OUT_OF_ORDER, f"stamp {stamp:.9f} s is older than the previous "
                             f"command's {self.last_stamp:.9f} s")
        if stamp < now - self.stale_after:
            return Rejection(topic, STALE, f"stamp {stamp:.9f} s is more than {self.stale_after} s older "
                             f"than the twin's time {now:.9f} s")
        if stamp > now + self.max_lead:
            return Rejection(topic, FUTURE, f"stamp {stamp:.9f} s is more than {self.max_lead} s ahead of "
                             f"the twin's time {now:.9f} s (stamp with the twin's /clock, or 0 for 'now')")
        return None

    def _reject(self, r: Rejection) -> Rejection:
        self.rejected += 1
        return r

    # -- inputs --------------------------------------------------------------------------------
    def command_array(self, topic: str, values, now: float) -> Rejection | None:
        """Lengths of every actuator in scene order (no stamp: they apply from ``now``)."""
        v = np.asarray(values, dtype=float).ravel()
        if v.size != len(self.names):
            return self._reject(Rejection(topic, SIZE, f"expected {len(self.names)} lengths "
                                          f"(actuators {list(self.names)}), got {v.size}"))
        r = self._check_lengths(topic, self.names, v)
        if r is not None:
            return self._reject(r)
        self._apply(self._all, v, None, now, now, stamp=0.0)
        return None

    def command_named(self, topic: str, names, lengths, velocities, stamp: float, now: float) -> Rejection | None:
        """Named lengths (m) with optional rates (m/s), stamped (0 → ``now``)."""
        names = list(names)
        lengths = np.asarray(lengths, dtype=float).ravel()
        vel = None if velocities is None or len(velocities) == 0 else np.asarray(velocities, dtype=float).ravel()
        if not names:
            return self._reject(Rejection(topic, SIZE, "no actuator names"))
        if lengths.size != len(names):
            return self._reject(Rejection(topic, SIZE, f"{len(names)} names but {lengths.size} lengths"))
        if vel is not None and vel.size != len(names):
            return self._reject(Rejection(topic, SIZE, f"{len(names)} names but {vel.size} velocities "
                                          "(expected the same number, or none)"))
        r = self._check_names(topic, names)
        idx = None if r else np.array([self.index[n] for n in names])
        r = r or self._check_lengths(topic, names, lengths, idx) or self._check_stamp(topic, stamp, now)
        if r is not None:
            return self._reject(r)
        if vel is not None and not np.all(np.isfinite(vel)):
            return self._reject(Rejection(topic, NOT_FINITE, f"velocities must be finite, got {vel.tolist()}"))
        self._apply(idx, lengths, vel, stamp if stamp > 0 else now, now, stamp=stamp)
        return None

    def command_trajectory(self, topic: str, names, stamp: float, points, now: float) -> Rejection | None:
        """``points``: sequence of (time_from_start s, positions (k,), velocities (k,) or empty)."""
        names = list(names)
        r = self._check_names(topic, names) or self._check_stamp(topic, stamp, now)
        if r is not None:
            return self._reject(r)
        if not points:
            return self._reject(Rejection(topic, BAD_TRAJECTORY, "no trajectory points"))
        t0 = stamp if stamp > 0 else now
        idx = np.array([self.index[n] for n in names])
        times, pos, vel = [], [], []
        for k, (tfs, p, v) in enumerate(points):
            p = np.asarray(p, dtype=float).ravel()
            if p.size != len(names):
                return self._reject(Rejection(topic, SIZE, f"point {k}: {p.size} positions for {len(names)} joint names"))
            r = self._check_lengths(topic, names, p, idx)
            if r is not None:
                return self._reject(Rejection(topic, r.kind, f"point {k}: {r.detail}"))
            if not math.isfinite(tfs) or (times and t0 + tfs <= times[-1]) or tfs < 0:
                return self._reject(Rejection(topic, BAD_TRAJECTORY, f"point {k}: time_from_start {tfs} s "
                                              "must be finite, ≥ 0 and increasing"))
            times.append(t0 + tfs)
            pos.append(p)
            vel.append(None if v is None or len(v) == 0 else np.asarray(v, dtype=float).ravel())
        use_rates = all(v is not None and v.size == len(names) and np.all(np.isfinite(v)) for v in vel)
        current = self.lengths_at(now)[idx].copy()
        if times[0] > now:        # start from the length in force now
            times.insert(0, now)
            pos.insert(0, current)
            vel.insert(0, np.zeros(len(names)))
        self.trajectory = _Trajectory(idx, np.array(times), np.array(pos),
                                      np.array(vel) if use_rates else None)
        self._mark_accepted(now, stamp)
        return None

    def _apply(self, idx, lengths, rates, t_ref, now, stamp) -> None:
        if self.trajectory is not None:    # a direct command takes these actuators off the trajectory
            keep = ~np.isin(self.trajectory.idx, idx)
            if not np.any(keep):
                self.trajectory = None
            elif not np.all(keep):
                tr = self.trajectory
                base_now = tr.at(now)
                self.base[tr.idx] = base_now
                self.rate[tr.idx] = 0.0
                self.t_ref[tr.idx] = now
                self.trajectory = _Trajectory(tr.idx[keep], tr.times, tr.lengths[:, keep],
                                              None if tr.rates is None else tr.rates[:, keep])
        if self._held is not None:        # back from a timeout: unaddressed actuators resume where they are
            self.base[:] = self._held_value(now)
            self.rate[:] = 0.0
            self.t_ref[:] = now
            self._held = None
        self.base[idx] = lengths
        self.rate[idx] = 0.0 if rates is None else rates
        self.t_ref[idx] = t_ref
        self._mark_accepted(now, stamp)

    def _mark_accepted(self, now: float, stamp: float) -> None:
        self.accepted += 1
        self.last_accept = now
        if stamp > 0:
            self.last_stamp = stamp
        self.newest_stamp = stamp

    # -- evaluation ----------------------------------------------------------------------------
    def _direct(self, t: float) -> np.ndarray:
        out = self._out
        np.multiply(self.rate, t - self.t_ref, out=out)
        out += self.base
        if self.trajectory is not None:
            out[self.trajectory.idx] = self.trajectory.at(t)
        return out

    def _held_value(self, t: float) -> np.ndarray:
        if self.behaviour == "hold" or self._held is None:
            return self._held
        s = min(max((t - self._t_hold) / self.ramp_time, 0.0), 1.0)
        w = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)     # C² smoothstep
        return self._held + w * (self.rest - self._held)

    def timed_out(self, t: float) -> bool:
        running = self.trajectory is not None and t < self.trajectory.times[-1]
        return not running and self.last_accept > -math.inf and t - self.last_accept > self.timeout

    def lengths_at(self, t: float) -> np.ndarray:
        """Commanded lengths (m) at simulated time ``t``, clamped to the stroke (a view: copy it)."""
        if self.timed_out(t):
            if self._held is None:
                self._t_hold = self.last_accept + self.timeout
                self._held = np.clip(self._direct(self._t_hold), self.stroke[:, 0], self.stroke[:, 1]).copy()
            self._out[:] = self._held_value(t)
            return self._out
        out = self._direct(t)
        np.clip(out, self.stroke[:, 0], self.stroke[:, 1], out=out)
        return out
