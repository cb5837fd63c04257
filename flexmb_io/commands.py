"""External actuator commands: validation and evaluation in simulated time (no ROS).

Three input forms, one per topic of the node (see :mod:`flexmb_io.topics`):

- an array of lengths in scene order (``Float64MultiArray``: no stamp, applies from reception);
- named lengths with optional rates, stamped (``ActuatorCommand``);
- a trajectory (``JointTrajectory``): points at ``stamp + time_from_start``, interpolated by cubic
  Hermite when every point has velocities, linearly otherwise; it starts from the length (and
  rate) in force when it arrives and holds its last point until a new command or the timeout,
  which counts from the trajectory's end.

A command stream is a sampled signal, not a staircase. A new length is reached over one
*observed command period* T — the mean of the last intervals between commands on the same input
that are not pauses, measured on the stamps when stamped and on arrival otherwise (a live node's
reception on the wall clock, mapped onto the twin's time; offline, the twin's time at
acceptance), bounded to [Δt, min(0.5 s, timeout)], Δt for the first command. Three holds
(``hold``):

- ``'smooth'`` (the default): a cubic Hermite from the (length, rate) in force at acceptance t_a
  to the commanded line's (length, rate) at t_a + T', continuous in length and rate (T' = T plus
  four times the spread of the intervals: a jittery stream's corrections spread out); the line is
  ``L + v (t − stamp)`` when the command has rates, else the parabola through the last three
  samples (exact for constant acceleration), followed one period past its segment and then faded
  to rest (a stream that stops);
- ``'ramp'``: lengths without rates by a first-order hold, the linear ramp from the length in force
  at t_a to the new length over [t_a, t_a + T] (continuous in length; at 100 Hz the twin follows
  the samples one period late, as any causal interpolation must); lengths with rates as in
  ``'smooth'``;
- ``'step'``: each length applies from the next step (the staircase of earlier versions).

When one command arrives per time step (T = Δt) the holds reach each length at the next step.

A message is accepted whole or rejected whole, with a :class:`Rejection` that names the topic,
a bounded excerpt of the offending value and what was expected. Commands that address only some
actuators leave the others on their current command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

# Rejection kinds (stable identifiers: tests and the status message use them)
SIZE, NOT_FINITE, STROKE, UNKNOWN_NAME, DUPLICATE_NAME, STALE, OUT_OF_ORDER, FUTURE, BAD_TRAJECTORY = (
    "size", "not_finite", "stroke", "unknown_name", "duplicate_name", "stale", "out_of_order", "future",
    "bad_trajectory")
BAD_STAMP, RATE, TOO_LARGE = "bad_stamp", "rate", "too_large"
# refused unapplied by the node: its publisher had stalled and could not have recorded the command
PUBLISHER_STALLED = "publisher_stalled"

HOLDS = ("smooth", "ramp", "step")
MAX_HOLD_PERIOD = 0.5        # s: longest ramp (commands slower than this are still held over 0.5 s)
STALL_GRACE = 0.03           # s: a bare-length stream's line is followed this long past its hold, then fades
# s over which a moving command stops when its timeout starts (a frozen line is a velocity step:
# measured 3–4 kN leg force peaks on the Stewart twin at the end of a 0.3 m/s stream)
TIMEOUT_STOP = 0.1
_PERIOD_WINDOW = 8           # intervals in the mean of the observed command period
# most samples of a bare stream taken as lost between two arrivals (a later arrival is a stall);
# 16: a keep-last history of 10 overwritten while the executor stalled lost 9 and 15 in a row of a
# 1 kHz stream in live runs
_MAX_LOST = 16
_EXCERPT = 6                 # values quoted in a rejection message
_NAME_CHARS = 40             # characters of one name quoted in a rejection message


def _short(x) -> str:
    s = x if isinstance(x, str) else (f"{x:.6g}" if isinstance(x, (float, np.floating)) else repr(x))
    return s if len(s) <= _NAME_CHARS else s[:_NAME_CHARS] + "…"


def excerpt(values, limit: int = _EXCERPT) -> str:
    """``[a, b, …]`` with at most ``limit`` items (each at most 40 characters) and the total count."""
    n = len(values)
    head = ", ".join(_short(values[i]) for i in range(min(n, limit)))
    return f"[{head}]" if n <= limit else f"[{head}, … ({n} in all)]"


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
    idx: np.ndarray          # (k,) actuator indices (int64)
    times: np.ndarray        # (m,) s, increasing, times[0] = acceptance time
    lengths: np.ndarray      # (m, k) m
    rates: np.ndarray | None  # (m, k) m/s, or None → linear

    def at(self, t: float, rate: bool = False) -> np.ndarray:
        """Lengths (m) at ``t``, or with ``rate`` their rates (m/s)."""
        ts = self.times
        if t <= ts[0] or t >= ts[-1]:
            if rate:
                return np.zeros(self.idx.size) if self.rates is None or t > ts[-1] or t < ts[0] else \
                    self.rates[0 if t <= ts[0] else -1].copy()
            return self.lengths[0] if t <= ts[0] else self.lengths[-1]
        j = int(np.searchsorted(ts, t, side="right")) - 1
        h = ts[j + 1] - ts[j]
        s = (t - ts[j]) / h
        l0, l1 = self.lengths[j], self.lengths[j + 1]
        if self.rates is None:
            return (l1 - l0) / h if rate else l0 + s * (l1 - l0)
        return _hermite(s, h, l0, self.rates[j], l1, self.rates[j + 1], rate)


def _hermite(s, h, p0, v0, p1, v1, rate: bool = False):
    """Cubic Hermite on [0, h] at s = t/h ∈ [0, 1]: value, or with ``rate`` its time derivative."""
    if rate:
        d00, d10 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1
        d01, d11 = -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
        return (d00 * p0 + d01 * p1) / h + d10 * v0 + d11 * v1
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * p0 + h10 * h * v0 + h01 * p1 + h11 * h * v1


@njit(cache=True, nogil=True)
def _evaluate_lines(t, base, rate, acc, acc_end, t_ref, fade_t, fade_T, seg_t0, seg_end, seg_p0, seg_v0, seg_cubic,
                    lengths, rates):
    """Commanded lengths (m) and rates (m/s) of every actuator at ``t`` into ``lengths, rates (na,)``:
    the line ``base + rate (t − t_ref)``, bent by the acceleration ``acc`` from ``t_ref`` to
    ``acc_end`` (the samples' parabola, carried over a few lost samples) and straight after (its
    rate fading linearly to 0 over ``fade_T`` from ``fade_t`` ≥ ``acc_end``, then frozen) and,
    while ``t < seg_end``, the hold segment from ``seg_p0`` (rate ``seg_v0``) at ``seg_t0``:
    linear onto ``base``, or (``seg_cubic``) the cubic Hermite onto the
    line's length and rate at the segment's end. One call for what the node evaluates at every
    step and every command (numpy on six-element arrays cost ~20 µs of interpreter per call)."""
    for i in range(base.size):
        e = t - t_ref[i]
        ea = max(0.0, min(t, acc_end[i]) - t_ref[i])     # s of the line's bend so far
        v = rate[i] + acc[i] * ea
        if t > fade_t[i]:
            tau = min(t - fade_t[i], fade_T[i])
            e = fade_t[i] - t_ref[i] + tau - tau * tau / (2.0 * fade_T[i])
            v = v * (1.0 - tau / fade_T[i])
        length = rate[i] * e + base[i]
        if ea > 0.0:
            length += acc[i] * (ea * e - 0.5 * ea * ea)
        if t < seg_end[i]:
            t0, t1 = seg_t0[i], seg_end[i]
            h = t1 - t0
            sv = min(max((t - t0) / h, 0.0), 1.0)
            p0 = seg_p0[i]
            if seg_cubic[i]:
                v0, v1 = seg_v0[i], rate[i]
                p1 = base[i] + v1 * (t1 - t_ref[i])
                s2 = sv * sv
                s3 = s2 * sv
                length = ((2.0 * s3 - 3.0 * s2 + 1.0) * p0 + (s3 - 2.0 * s2 + sv) * h * v0
                          + (-2.0 * s3 + 3.0 * s2) * p1 + (s3 - s2) * h * v1)
                v = (((6.0 * s2 - 6.0 * sv) * p0 + (-6.0 * s2 + 6.0 * sv) * p1) / h
                     + (3.0 * s2 - 4.0 * sv + 1.0) * v0 + (3.0 * s2 - 2.0 * sv) * v1)
            else:
                length = p0 + sv * (base[i] - p0)
                v = (base[i] - p0) / h
        lengths[i] = length
        rates[i] = v


@njit(cache=True, nogil=True)
def _bound_joins(idx, now, a_max, h_max, base, rate, acc, t_ref, seg_p0, seg_v0, seg_end, fade_t):
    """Lengthen the cubic joins of actuators ``idx`` (starting at ``now``) until the commanded
    length's acceleration stays within ``a_max`` (m/s²), at most to ``h_max`` (s). A cubic's
    acceleration is linear in time, so it peaks at an end of the join:
    ``(6d − 2h(2v₀ + v₁))/h²`` and ``(−6d + 2h(v₀ + 2v₁))/h²`` with ``d`` the join's rise onto the
    line. A join that already complies is left as it is (bit for bit); the line's fade starts no
    earlier than the join's new end, and a lengthened join's line is straight (``acc`` 0)."""
    for j in range(idx.size):
        i = idx[j]
        h = seg_end[i] - now
        v0 = seg_v0[i]
        v1 = rate[i]
        for _ in range(64):
            d = base[i] + v1 * (now + h - t_ref[i]) - seg_p0[i]
            a = max(abs(6.0 * d - 2.0 * h * (2.0 * v0 + v1)), abs(-6.0 * d + 2.0 * h * (v0 + 2.0 * v1))) / (h * h)
            if a <= a_max or h >= h_max:
                break
            h = min(1.25 * h, h_max)
        if now + h != seg_end[i]:
            seg_end[i] = now + h
            acc[i] = 0.0
            if fade_t[i] < seg_end[i]:
                fade_t[i] = seg_end[i]


@njit(cache=True, nogil=True)
def _grid_steps(h, grid):
    """``h`` (s, > 0) between two unstamped samples as whole steps of their clock's ``grid`` (at
    least one; more where samples were lost in between, :meth:`_Period.observe`), in s."""
    return grid * max(1.0, round(h / grid))


@njit(cache=True, nogil=True)
def _predict_lines(idx, lengths, tau, stamped, grid, T, dt1, hist_L, hist_t, hist_n, hist_stamped, base, rate,
                   acc_out):
    """The parabola through each new sample ``lengths[j]`` (actuator ``idx[j]``, sample time ``tau``)
    and its previous two (``hist_*``, shifted in here), evaluated ``dt1`` after ``tau``: its length
    into ``base[idx[j]]``, its rate into ``rate[idx[j]]``, its acceleration into ``acc_out[idx[j]]``.
    See :meth:`CommandSchedule._predict`."""
    for j in range(idx.size):
        i = idx[j]
        hl0, hl1 = hist_L[i, 0], hist_L[i, 1]
        ht0, ht1 = hist_t[i, 0], hist_t[i, 1]
        h1 = tau - ht0
        h2 = ht0 - ht1
        near = 2.5 * T
        if not stamped:
            if h1 > 0.0:
                h1 = _grid_steps(h1, grid)
            if h2 > 0.0:
                h2 = _grid_steps(h2, grid)
            near = max(near, (_MAX_LOST + 1.5) * grid)
        n = hist_n[i] if (hist_stamped[i] == stamped and h1 > 0.0 and h1 <= near) else 0
        if n == 2 and not (h2 > 0.0 and h2 <= near):
            n = 1
        h1s = h1 if n >= 1 else 1.0
        h2s = h2 if n == 2 else 1.0
        x = lengths[j]
        d1 = (x - hl0) / h1s if n >= 1 else 0.0
        d2 = (hl0 - hl1) / h2s
        acc = 2.0 * (d1 - d2) / (h1s + h2s) if n == 2 else 0.0
        vel = d1 + 0.5 * acc * (h1s if n >= 1 else 0.0)
        hist_L[i, 1] = hl0
        hist_t[i, 1] = ht0
        hist_L[i, 0] = x
        hist_t[i, 0] = tau
        hist_n[i] = min(n + 1, 2)
        hist_stamped[i] = stamped
        base[i] = x + vel * dt1 + 0.5 * acc * dt1 * dt1
        rate[i] = vel + acc * dt1
        acc_out[i] = acc


@njit(cache=True, nogil=True)
def _interval_stats(iv):
    """(mean, spread) of the intervals ``iv`` that are not pauses (> 3 × their median); the spread
    is their range without the two shortest and the two longest (with 8 or more): a late delivery
    or two among the window (DDS hiccups) must not lengthen every hold for the next 32 commands
    (measured over real DDS with the full range: 4 kN leg force peaks at 100 Hz after one 1 ms
    interval), while a stream that jitters throughout keeps its long holds."""
    srt = np.sort(iv)
    m = srt.size
    med = srt[m // 2] if m % 2 else 0.5 * (srt[m // 2 - 1] + srt[m // 2])
    kept = srt[srt <= 3.0 * med] if med > 0.0 else srt
    k = kept.size
    trim = 2 if k >= 8 else 0
    return kept.mean(), kept[k - 1 - trim] - kept[trim]


@njit(cache=True, nogil=True)
def _arrival_slope(arrivals, counts, m, newest):
    """Least-squares slope (s per sample) of arrival time against sample count over the last ``m``
    arrivals of the rings ``arrivals, counts (W,)`` (the newest at ``newest % W``, ``newest ≥ m −
    1``; ``counts``: each arrival's sample number, which skips the samples taken as lost)."""
    w = arrivals.size
    ref = arrivals[newest % w]              # relative times: no cancellation at large t
    ref_x = counts[newest % w]
    first = newest - (m - 1)
    mean_y = 0.0
    mean_x = 0.0
    for j in range(m):
        mean_y += arrivals[(first + j) % w] - ref
        mean_x += counts[(first + j) % w] - ref_x
    mean_y /= m
    mean_x /= m
    sxy = 0.0
    sxx = 0.0
    for j in range(m):
        dx = counts[(first + j) % w] - ref_x - mean_x
        sxy += dx * (arrivals[(first + j) % w] - ref - mean_y)
        sxx += dx * dx
    return sxy / sxx


@njit(cache=True, nogil=True)
def _arrival_envelope(arrivals, counts, m, newest, hull):
    """The line under the last ``m`` arrivals of the rings ``arrivals, counts (W,)`` (as
    :func:`_arrival_slope`) that lies closest to them: (its slope in s per sample, its value at the
    newest arrival's sample number). ``hull (W,)`` int scratch.

    A transport only ever delays a sample, so the sender's regular clock runs under the arrivals,
    touching the least delayed ones: of the lines under every point, the one with the least summed
    distance to them is an edge of their lower convex hull, the one over their mean sample number
    (Moon, Skelly & Towsley, "Estimation and removal of clock skew from network delay
    measurements", INFOCOM 1999); at a hull vertex, the later edge. A late first sample is then
    above the line instead of tilting it, as it tilts a least-squares fit (measured: the Stewart
    appendix law at 100 Hz with its first sample 3.6 ms late: 1.7 kN leg force peaks, 157 N on
    time)."""
    w = arrivals.size
    ref = arrivals[newest % w]              # relative times: no cancellation at large t
    ref_x = counts[newest % w]
    first = newest - (m - 1)
    top = 0
    mean_x = 0.0
    for j in range(m):
        r = (first + j) % w
        x, y = counts[r] - ref_x, arrivals[r] - ref
        mean_x += x
        while top >= 2:
            a, b = hull[top - 2], hull[top - 1]
            xa, ya = counts[a] - ref_x, arrivals[a] - ref
            xb, yb = counts[b] - ref_x, arrivals[b] - ref
            if (xb - xa) * (y - ya) - (yb - ya) * (x - xa) > 0.0:
                break                       # a left turn: b stays on the lower hull
            top -= 1
        hull[top] = r
        top += 1
    mean_x /= m
    e = 0
    while e < top - 2 and counts[hull[e + 1]] - ref_x <= mean_x:
        e += 1
    a, b = hull[e], hull[e + 1]
    slope = (arrivals[b] - arrivals[a]) / (counts[b] - counts[a])
    return slope, arrivals[a] - ref + slope * (ref_x - counts[a]) + ref


class _Period:
    """One input's observed command period and, for unstamped commands, a de-jittered sample clock.

    The period is the mean of the last intervals that are not pauses (≤ 3× their median): arrival
    jitter does not accumulate in a mean, where a median of quantized, jittered intervals is biased.
    Its spread (their range, the two shortest and longest left out) is 0 for a regular stream.

    Arrival times (delayed by the transport and the sender's jitter; offline, quantized to the
    twin's steps) are mapped onto a
    regular sample clock: with the phase error ``e = a_k − (τ_k−1 + T̂)``, ``τ_k = τ_k−1 + T̂ + β e``
    (a phase-locked loop: the clock moves by a fraction of a µs per sample where the arrivals jitter
    by milliseconds — what the rate and acceleration estimates of the samples need). While the
    clock is young (fewer than half of ``CLOCK_WINDOW`` arrivals) its step and its phase are the
    line under its arrivals (:func:`_arrival_envelope`: a late first sample must not set them);
    then its step T̂ follows the least-squares slope of arrival time against sample count over the
    last ``CLOCK_WINDOW`` arrivals on this clock with a gain of ``SMOOTH`` per arrival, so that its
    wobble does not modulate every rate estimate: a transport that holds samples
    back and hands them over together (a hiccup, then a burst) moves single intervals, and a mean of
    intervals with the pauses left out, but not the slope. Measured over DDS before (T̂ the mean of
    intervals, then moved by γe per sample, γ = β²/4): a 100 Hz stream whose first 18 commands came
    1 ms apart left T̂ at 5.2 ms for good, the clock drifted by half a period per sample, and the
    predicted lines, on a grid half the true spacing, ran the legs to their stroke ends (0.8 MN).
    Samples lost on the way (9 % of a 1 kHz stream in live runs) are counted (:meth:`observe`), so
    the clock and the sample spacing skip them (README "Bare streams over real DDS").

    The clock restarts on an arrival (a new stream, a pause, lost samples) when the phase error
    exceeds ``3 T̂ + 4 × spread`` for ``LATE_RUN`` arrivals in a row that do not catch up (an error
    not falling by T̂/2 per arrival), or ``PAUSE`` s plus that bound once: the first late arrival
    after a stall of the sender or the transport is the head of a backlog that the next ones catch
    up (measured: a Python client that stalled 48 ms sent the 48 commands it owed back to back; a
    restart there moves the targets by v × 48 ms).

    The gains β and ``SMOOTH`` are per sample up to 100 Hz and per second above
    (``BETA_PER_S``, ``SMOOTH_PER_S``: the same time constants, 2 s and 0.2 s, at any rate). Per
    sample at 1 kHz, each arrival's jitter moved the clock ten times as often: with receptions
    jittered by 0–0.3 ms, a 40 nm wobble of the commanded lengths that the steel legs turned into
    ±8 N (177 N peaks against 160 N smooth; 162 N with the gains per second, 160 N with a frozen
    clock)."""

    WINDOW = 32
    CLOCK_WINDOW = 64
    BETA = 0.005
    BETA_PER_S = 0.5
    LATE_RUN = 3
    PAUSE = 0.1
    SMOOTH = 0.05
    SMOOTH_PER_S = 5.0
    MIN_SLOPE = 3                   # arrivals on a clock before its step is their slope

    def __init__(self):
        self.intervals = np.zeros(self.WINDOW)
        self.n = 0
        self.last = {True: math.nan, False: math.nan}    # stamped → last stamp; else last arrival
        self.arrivals = np.zeros(self.CLOCK_WINDOW)      # ring: arrivals on the current clock
        self.counts = np.zeros(self.CLOCK_WINDOW)        # ring: their sample numbers on it
        self._hull = np.zeros(self.CLOCK_WINDOW, dtype=np.int64)   # scratch of _arrival_envelope
        self.count = 0                                   # sample number of the newest arrival
        self.run = 0                                     # arrivals on the current clock
        self.late = 0                                    # late arrivals in a row, not catching up
        self.e_prev = 0.0                                # the previous arrival's phase error
        self.tau = math.nan
        self.T_hat = math.nan

    def observe(self, t: float, stamped: bool, floor: float,
                gap_steps=None) -> tuple[float | None, float, float, float]:
        """(period or None for the first command, its spread, the sample time τ, the clock's step)
        of a command at ``t`` (its stamp, or its arrival); ``floor`` (s) is the smallest clock step.

        An unstamped arrival about k − 1 periods later than the clock expects (k ≤ 1 +
        :data:`_MAX_LOST`) is either late or the k-th sample after the previous one, the ones
        between lost (a best-effort subscription, a keep-last history overwritten while the
        executor was busy: 9 % of a 1 kHz stream in live runs). Arrival times cannot tell the two
        apart; ``gap_steps(k)`` — the values — decides: the number of steps j ≤ k on from the
        previous sample that the new one continues the previous ones' motion best (1: none fits
        better than the next). Taken as lost, the clock moves j periods, and what the arrival is
        later than that is lateness (a late sample moved by one period made a lost one a step of
        twice the rate: 8.5 kN leg force peaks on the Stewart twin at 3 % loss, 160 N smooth; the
        clock moved by the arrival's k periods, a sender that stalled and then lost part of its
        backlog put the samples 5 ms ahead of their values: 45 m/s² command accelerations)."""
        prev = self.last[stamped]
        self.last[stamped] = t
        if math.isfinite(prev):
            self.intervals[self.n % self.WINDOW] = t - prev
            self.n += 1
        est, spread = None, 0.0
        if self.n:
            est, spread = _interval_stats(self.intervals[:min(self.n, self.WINDOW)])
        if stamped:
            return est, spread, t, max(est or 0.0, floor)
        if self.run == 0:
            return est, spread, self._restart(t, est, floor), self.T_hat
        if self.run < self.MIN_SLOPE:     # no slope yet: the mean of the intervals
            self.T_hat = max(est or 0.0, floor)
        e = t - (self.tau + self.T_hat)
        bound = 3.0 * self.T_hat + 4.0 * spread
        # late, and not a backlog catching up (whose arrivals come faster than the clock, so the
        # error falls by about T̂ per sample)
        catching_up = e < self.e_prev - 0.5 * self.T_hat
        self.late = self.late + 1 if (e > bound and not catching_up) else 0
        self.e_prev = e
        if self.late >= self.LATE_RUN or e > bound + self.PAUSE:
            return est, spread, self._restart(t, est, floor), self.T_hat
        steps = 1                                # sample periods since the previous arrival
        if gap_steps is not None and e > 0.5 * self.T_hat:
            steps = min(1 + int(round(e / self.T_hat)), 1 + _MAX_LOST)
            steps = gap_steps(steps) if steps > 1 else 1
            if steps > 1:
                e -= (steps - 1) * self.T_hat      # on time for that sample
                self.late = 0
                self.e_prev = e
            else:
                steps = 1
        self.tau += steps * self.T_hat + min(self.BETA, self.BETA_PER_S * self.T_hat) * e
        self.count += steps
        cw = self.CLOCK_WINDOW
        self.arrivals[self.run % cw] = t
        self.counts[self.run % cw] = self.count
        self.run += 1
        m = min(self.run, cw)
        if m >= self.MIN_SLOPE and m < cw // 2:
            # a young clock: its step and phase are the line under its arrivals (not accumulated
            # from the first arrival's phase, which may be late: _arrival_envelope)
            slope, self.tau = _arrival_envelope(self.arrivals, self.counts, m, self.run - 1, self._hull)
            self.T_hat = max(slope, floor)
        elif m >= self.MIN_SLOPE:
            slope = _arrival_slope(self.arrivals, self.counts, m, self.run - 1)
            # followed at a rate of SMOOTH per sample: its wobble would modulate every rate estimate
            gain = min(self.SMOOTH, self.SMOOTH_PER_S * self.T_hat)
            self.T_hat = max(self.T_hat + gain * (slope - self.T_hat), floor)
        return est, spread, self.tau, self.T_hat

    def _restart(self, t: float, est: float | None, floor: float) -> float:
        """The clock anew on the arrival ``t``: its sample time."""
        self.arrivals[0] = t
        self.counts[0] = 0.0
        self.count = 0
        self.run = 1
        self.late = 0
        self.e_prev = 0.0
        self.tau = t
        self.T_hat = max(est or 0.0, floor)
        return t


class CommandSchedule:
    """The commanded actuator lengths as a function of simulated time.

    Parameters
    ----------
    names : actuator names, scene order (na,)
    stroke : (na, 2) admissible lengths (m), inclusive
    rest : (na,) lengths at start (m): held until the first command, target of ``ramp_to_rest``
    timeout : s of simulated time without a command after which the timeout behaviour starts
        (``inf`` disables it); for a trajectory it counts from its last point
    behaviour : ``hold`` (keep the last length, stop extrapolating) or ``ramp_to_rest``
    ramp_time : s, duration of the smooth ramp to ``rest``
    stale_after : s, stamped commands older than ``now − stale_after`` are rejected
    max_lead : s, stamped commands later than ``now + max_lead`` are rejected (clock mismatch)
    hold : ``smooth`` (cubic Hermite over the observed command period), ``ramp`` (first-order hold
        of bare lengths) or ``step`` (the module's docstring)
    dt : s, the twin's time step: the shortest hold and the first command's period
    max_rate : m/s, scalar or (na,): commanded rates beyond it are rejected (the servo's
        ``max_rate`` where one is declared, ``max_command_rate`` otherwise)
    max_points : most points a trajectory may have
    max_accel : m/s², most acceleration of the commanded length while a smooth (cubic) hold joins
        a new command's line: a join that would need more is lengthened (up to
        ``MAX_HOLD_PERIOD``). A regular stream's joins are far below it and stay as they are; a
        command whose line disagrees with the length in force — a late stamp extrapolated, a
        clock that jumped, a step — is reached over a time a real actuator could, not in one
        Δt (measured: a player whose twin-time estimate went stale by ~0.5 s made 1.5 cm kinks
        in one step, 15 000 m/s², and the frame-leg twin's Newton iterations per step rose from
        1.2 to 11 and then stalled). ``inf`` disables it.
    """

    def __init__(self, names, stroke: np.ndarray, rest: np.ndarray, *, timeout: float = math.inf,
                 behaviour: str = "hold", ramp_time: float = 1.0, stale_after: float = 1.0,
                 max_lead: float = 1.0, hold: str = "smooth", dt: float = 1e-3, max_rate=10.0,
                 max_points: int = 10000, max_accel: float = math.inf):
        if behaviour not in ("hold", "ramp_to_rest"):
            raise ValueError(f"timeout behaviour must be 'hold' or 'ramp_to_rest', got {behaviour!r}")
        if hold not in HOLDS:
            raise ValueError(f"command hold must be one of {list(HOLDS)}, got {hold!r}")
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a positive number of s, got {dt!r}")
        self.names = tuple(names)
        self.index = {n: i for i, n in enumerate(self.names)}
        self.stroke = np.asarray(stroke, dtype=float)
        # admissible lengths: the stroke, and always > 0 (an undeclared stroke is [0, inf])
        self._lo = np.maximum(self.stroke[:, 0], np.nextafter(0.0, 1.0))
        self._hi = self.stroke[:, 1].copy()
        na = len(self.names)
        self._all = np.arange(na, dtype=np.int64)
        self.rest = np.asarray(rest, dtype=float).copy()
        self.timeout, self.behaviour, self.ramp_time = timeout, behaviour, ramp_time
        self.stale_after, self.max_lead = stale_after, max_lead
        self.hold, self.dt, self.max_points = hold, float(dt), int(max_points)
        self.max_rate = np.broadcast_to(np.asarray(max_rate, dtype=float), (na,)).copy()
        if not max_accel > 0.0:
            raise ValueError(f"max_accel must be > 0 m/s² (inf: unbounded), got {max_accel!r}")
        self.max_accel = float(max_accel)
        self.max_period = max(self.dt, min(MAX_HOLD_PERIOD, timeout))
        # the commanded line L(t) = base + rate (t − t_ref), per actuator
        self.base = self.rest.copy()         # m, length at the reference time
        self.rate = np.zeros(na)             # m/s
        self.t_ref = np.zeros(na)            # s, reference time of base (the stamp)
        self.acc = np.zeros(na)              # m/s², the line's bend after t_ref (the samples' parabola)
        self.acc_end = np.zeros(na)          # s, … until then
        # the hold segment that joins the previous command to the line: [seg_t0, seg_end)
        self.seg_t0 = np.zeros(na)
        self.seg_end = np.full(na, -math.inf)
        self.seg_p0 = np.zeros(na)           # m, length in force at acceptance
        self.seg_v0 = np.zeros(na)           # m/s, rate in force at acceptance (Hermite)
        self.seg_cubic = np.zeros(na, dtype=bool)
        # smooth hold of bare lengths: the target is the parabola through the last three samples
        # (exact for constant acceleration), at the segment's end; after it the line is followed
        # for one more period (a late sample), then its rate fades to rest over one period
        self.fade_t = np.full(na, math.inf)  # s, start of the fade (inf: an explicit line, no fade)
        self.fade_T = np.ones(na)            # s, its duration
        self.hist_L = np.zeros((na, 2))      # m, the previous two samples of each actuator, newest first
        self.hist_t = np.zeros((na, 2))      # s, their sample times
        self.hist_n = np.zeros(na, dtype=np.int64)   # how many of them are usable (0–2)
        self.hist_stamped = np.zeros(na, dtype=bool)
        self._e = np.zeros(na)
        self._periods: dict[str, _Period] = {}
        self._grid = self.dt                 # s, grid step of the newest unstamped command's clock
        self.last_period = self.dt           # s, the period of the newest hold (for reports and tests)
        self.trajectory: _Trajectory | None = None
        self.last_accept = -math.inf         # sim time of the newest accepted command
        self.last_stamp = -math.inf          # newest accepted stamp (ordering check)
        self.newest_stamp = 0.0              # stamp of the newest accepted command (0 for arrays)
        self._held: np.ndarray | None = None  # lengths when the timeout started
        self._held_v = np.zeros(len(self.names))  # m/s, their rates then (they stop over TIMEOUT_STOP)
        self._t_hold = 0.0
        self._out = np.zeros(na)
        self._out_rate = np.zeros(na)
        self._line = np.zeros(na)
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
            bad = [f"{_short(n)}={v}" for n, v in zip(names, values) if not math.isfinite(v)]
            return Rejection(topic, NOT_FINITE, f"lengths must be finite, got {excerpt(bad)}")
        bad = [f"{_short(n)}={v:.6g} m (stroke [{a:.6g}, {b:.6g}] m)"
               for n, v, a, b, o in zip(names, values, lo, hi, ok) if not o]
        return Rejection(topic, STROKE, "lengths outside the actuator stroke: " + ", ".join(bad[:_EXCERPT])
                         + (f", … ({len(bad)} in all)" if len(bad) > _EXCERPT else ""))

    def _check_rates(self, topic: str, names, rates: np.ndarray, idx: np.ndarray,
                     points: np.ndarray | None = None) -> Rejection | None:
        """Finite and within the rate limit: ``rates (k,)`` of actuators ``idx``, or ``(m, k)`` rows of
        the trajectory points ``points (m,)``. One vectorized test; messages on failure only."""
        r2 = rates.reshape(-1, idx.size)
        lim = self.max_rate[idx]
        ok = np.abs(r2) <= lim                 # NaN fails too
        if ok.all():
            return None
        j = int(np.flatnonzero(~ok.all(axis=1))[0])
        where = "" if points is None else f"point {int(points[j])}: "
        row = r2[j]
        if not np.all(np.isfinite(row)):
            bad = [f"{_short(n)}={v}" for n, v in zip(names, row) if not math.isfinite(v)]
            return Rejection(topic, NOT_FINITE, f"{where}velocities must be finite, got {excerpt(bad)}")
        bad = [f"{_short(n)}={v:.6g} m/s (limit {lm:.6g} m/s)" for n, v, lm in zip(names, row, lim) if abs(v) > lm]
        return Rejection(topic, RATE, f"{where}rates beyond the actuator rate limit (the servo's max_rate where "
                         f"declared, else the max_command_rate parameter): {excerpt(bad)}")

    def _check_names(self, topic: str, names) -> Rejection | None:
        unknown = [n for n in names if n not in self.index]
        if unknown:
            return Rejection(topic, UNKNOWN_NAME, f"unknown actuator names {excerpt(unknown)}; "
                             f"this twin has {excerpt(self.names, 12)}")
        if len(set(names)) != len(names):
            seen, rep = set(), []
            for n in names:
                if n in seen:
                    rep.append(n)
                seen.add(n)
            return Rejection(topic, DUPLICATE_NAME, f"actuator names repeated: {excerpt(rep)} "
                             f"(each name at most once per message)")
        return None

    def _check_stamp(self, topic: str, stamp: float, now: float) -> Rejection | None:
        if not math.isfinite(stamp) or stamp < 0.0:
            return Rejection(topic, BAD_STAMP, f"header stamp {stamp:.9g} s is negative; expected the time the "
                             "command is meant for on the twin's /clock (≥ 0), or 0 for 'now'")
        if stamp == 0.0:
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
    def command_array(self, topic: str, values, now: float, arrival: float | None = None) -> Rejection | None:
        """Lengths of every actuator in scene order (no stamp: they apply from ``now``).

        ``arrival`` (s): the twin time the command arrived at, on the wall clock's mapping onto the
        twin's (see :meth:`_period`); None: ``now``."""
        v = np.asarray(values, dtype=float).ravel()
        if v.size != len(self.names):
            return self._reject(Rejection(topic, SIZE, f"expected {len(self.names)} lengths "
                                          f"(actuators {excerpt(self.names, 12)}), got {v.size}: {excerpt(v)}"))
        r = self._check_lengths(topic, self.names, v)
        if r is not None:
            return self._reject(r)
        self._apply(topic, self._all, v, None, now, now, stamp=0.0, arrival=arrival)
        return None

    def command_named(self, topic: str, names, lengths, velocities, stamp: float, now: float,
                      arrival: float | None = None) -> Rejection | None:
        """Named lengths (m) with optional rates (m/s), stamped (0 → ``now``; ``arrival`` as in
        :meth:`command_array`)."""
        names = list(names)
        lengths = np.asarray(lengths, dtype=float).ravel()
        vel = None if velocities is None or len(velocities) == 0 else np.asarray(velocities, dtype=float).ravel()
        if not names:
            return self._reject(Rejection(topic, SIZE, f"no actuator names (expected some of {excerpt(self.names)})"))
        if lengths.size != len(names):
            return self._reject(Rejection(topic, SIZE, f"{len(names)} names but {lengths.size} lengths "
                                          "(expected one length per name)"))
        if vel is not None and vel.size != len(names):
            return self._reject(Rejection(topic, SIZE, f"{len(names)} names but {vel.size} velocities "
                                          "(expected the same number, or none)"))
        r = self._check_names(topic, names)
        idx = None if r else np.array([self.index[n] for n in names], dtype=np.int64)
        r = r or self._check_lengths(topic, names, lengths, idx) or self._check_stamp(topic, stamp, now)
        if r is None and vel is not None:
            r = self._check_rates(topic, names, vel, idx)
        if r is not None:
            return self._reject(r)
        self._apply(topic, idx, lengths, vel, stamp if stamp > 0 else now, now, stamp=stamp, arrival=arrival)
        return None

    def command_trajectory(self, topic: str, names, stamp: float, points, now: float) -> Rejection | None:
        """``points``: sequence of (time_from_start s, positions (k,), velocities (k,) or empty).

        Validated vectorized over the points (a 10⁴-point trajectory costs milliseconds); at most
        ``max_points`` points."""
        m = len(points)
        if m > self.max_points:
            return self._reject(Rejection(topic, TOO_LARGE, f"{m} trajectory points; the limit is "
                                          f"{self.max_points} (parameter max_trajectory_points)"))
        names = list(names)
        if not names:
            return self._reject(Rejection(topic, SIZE, "no joint_names; expected the names of the actuators the "
                                          f"trajectory drives (some of {excerpt(self.names)})"))
        r = self._check_names(topic, names) or self._check_stamp(topic, stamp, now)
        if r is not None:
            return self._reject(r)
        if m == 0:
            return self._reject(Rejection(topic, BAD_TRAJECTORY, "no trajectory points (expected at least one)"))
        k = len(names)
        idx = np.array([self.index[n] for n in names], dtype=np.int64)
        npos = np.fromiter((len(p[1]) for p in points), dtype=np.int64, count=m)
        bad = np.flatnonzero(npos != k)
        if bad.size:
            j = int(bad[0])
            return self._reject(Rejection(topic, SIZE, f"point {j}: {npos[j]} positions for {k} joint names "
                                          f"{excerpt(names)} (expected one per name)"))
        pos = np.array([p[1] for p in points], dtype=float).reshape(m, k)      # (m, k) m
        ok = (pos >= self._lo[idx]) & (pos <= self._hi[idx])
        if not ok.all():
            j = int(np.flatnonzero(~ok.all(axis=1))[0])
            r = self._check_lengths(topic, names, pos[j], idx)
            return self._reject(Rejection(topic, r.kind, f"point {j}: {r.detail}"))
        tfs = np.fromiter((p[0] for p in points), dtype=float, count=m)        # (m,) s
        okt = np.isfinite(tfs) & (tfs >= 0)
        okt[1:] &= tfs[1:] > tfs[:-1]
        if not okt.all():
            j = int(np.flatnonzero(~okt)[0])
            return self._reject(Rejection(topic, BAD_TRAJECTORY, f"point {j}: time_from_start {tfs[j]:.9g} s must be "
                                          f"finite, ≥ 0 and increasing (previous {tfs[j - 1] if j else math.nan:.9g} s)"))
        nvel = np.fromiter((0 if p[2] is None else len(p[2]) for p in points), dtype=np.int64, count=m)
        bad = np.flatnonzero((nvel != 0) & (nvel != k))
        if bad.size:
            j = int(bad[0])
            return self._reject(Rejection(topic, SIZE, f"point {j}: {nvel[j]} velocities for {k} joint names "
                                          "(expected one per name, or none)"))
        vel = None
        if nvel.any():
            withv = np.flatnonzero(nvel == k)
            vv = np.array([points[j][2] for j in withv], dtype=float).reshape(withv.size, k)
            r = self._check_rates(topic, names, vv, idx, points=withv)
            if r is not None:
                return self._reject(r)
            if withv.size == m:            # Hermite only when every point has rates; else linear
                vel = vv
        times = stamp + tfs if stamp > 0 else now + tfs
        cur, vcur = self._in_force(now)
        if times[0] > now:                 # start from the length (and rate) in force now
            times = np.concatenate(([now], times))
            pos = np.vstack((cur[idx], pos))
            if vel is not None:
                vel = np.vstack((vcur[idx], vel))
        self._leave_trajectory_and_timeout(idx, now, cur)
        self.seg_end[idx] = -math.inf
        self.hist_n[idx] = 0
        self.trajectory = _Trajectory(idx, times, pos, vel)
        self._mark_accepted(now, stamp)
        return None

    def _in_force(self, now: float) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the commanded lengths (m) and rates (m/s) in force at ``now`` (unclamped)."""
        if self.timed_out(now):
            self.lengths_at(now)               # sets the hold
            return self._held_value(now).copy(), self._held_rate(now)
        # the length in force is clamped to the stroke (a Hermite overshoot is cut there)
        return np.clip(self._direct(now), self.stroke[:, 0], self.stroke[:, 1]), self._direct_rate(now)

    def _leave_trajectory_and_timeout(self, idx, now: float, cur: np.ndarray) -> None:
        """Actuators ``idx`` get a new command: take them off a running trajectory; after a timeout the
        others resume on the lengths in force (``cur``)."""
        if self.trajectory is not None:
            tr = self.trajectory
            keep = ~np.isin(tr.idx, idx)
            if not np.any(keep):
                self.trajectory = None
            elif not np.all(keep):           # the rest stay on it: the dropped ones hold where they are
                gone = tr.idx[~keep]
                self.base[gone] = cur[gone]
                self.rate[gone] = 0.0
                self.acc[gone] = 0.0
                self.t_ref[gone] = now
                self.seg_end[gone] = -math.inf
                self.fade_t[gone] = math.inf
                self.trajectory = _Trajectory(tr.idx[keep], tr.times, tr.lengths[:, keep],
                                              None if tr.rates is None else tr.rates[:, keep])
        if self._held is not None:         # back from a timeout: unaddressed actuators resume where they are
            self.base[:] = cur
            self.rate[:] = 0.0
            self.acc[:] = 0.0
            self.t_ref[:] = now
            self.seg_end[:] = -math.inf
            self.fade_t[:] = math.inf
            self.hist_n[:] = 0
            self._held = None
            if self.trajectory is not None:
                self.trajectory = None

    def _period(self, topic: str, stamp: float, now: float, arrival: float | None, idx=None,
                lengths=None) -> tuple[float, float]:
        """(hold duration T, sample time τ) of a command on ``topic`` accepted at ``now`` that
        arrived at twin time ``arrival`` (None: ``now``); ``idx, lengths``: its actuators and
        lengths, which tell a lost sample from a late one.

        A live node passes the wall clock's arrival mapped onto the twin's time (the twin time whose
        deadline that wall time is), not the twin's time at acceptance: that one is quantized to
        steps and stands still while the stepping thread is late, so a late step made samples that
        came 1 ms apart look simultaneous and then 2–3 ms apart (1 kHz bare streams: 0.4–5.5 kN leg
        force peaks against 136 N smooth)."""
        fits = (lambda k: self._lost_steps(idx, lengths, k)) if stamp <= 0 and idx is not None else None
        period = self._periods.setdefault(topic, _Period())
        est, spread, tau, grid = period.observe(stamp if stamp > 0 else (now if arrival is None else arrival),
                                                stamp > 0, self.dt, fits)
        self._grid = grid
        # a cubic hold lasts the period plus four times the spread of the intervals: corrections of a
        # jittery stream (a late or early sample moves the target by v × jitter) are spread over
        # more than the jitter, while a regular stream keeps T = its period
        T = self.dt if est is None else est + (4.0 * spread if self.hold == "smooth" else 0.0)
        T = min(max(T, self.dt), self.max_period)
        # a period within rounding of one step is one step: the hold then ends exactly at t_a + Δt,
        # the time the next step evaluates, which makes one command per step the plain step hold
        return (self.dt if T <= self.dt * (1.0 + 1e-6) else T), tau

    def _lost_steps(self, idx, lengths, k: int) -> int:
        """The grid steps j ∈ [1, k] from each actuator's previous sample to the unstamped ``lengths``
        of actuators ``idx`` that continue the line through its previous two samples best (the
        deviations summed over the actuators with two such samples); 1 without any, or with no
        motion."""
        grid = self._grid
        cost = np.zeros(k)
        js = np.arange(1, k + 1) * grid
        for j, i in enumerate(idx):
            if self.hist_n[i] < 2 or self.hist_stamped[i]:
                continue
            h2 = _grid_steps(self.hist_t[i, 0] - self.hist_t[i, 1], grid)
            slope = (self.hist_L[i, 0] - self.hist_L[i, 1]) / h2
            cost += np.abs(lengths[j] - self.hist_L[i, 0] - slope * js)
        best = int(np.argmin(cost))
        return 1 + best if cost[best] < cost[0] else 1

    def _predict(self, idx, lengths, tau: float, stamped: bool, T: float, t1: float, on_wall: bool = False) -> None:
        """Length and rate at ``t1`` of the parabola through the new samples ``lengths`` (at ``τ``) and
        the previous two of each actuator (a line with one, a constant with none usable), into
        ``base[idx]`` and ``rate[idx]``; the history is usable when on the same clock and at most
        2.5 T apart. Unstamped samples are taken as regular: differences on the grid step, not on the
        de-jittered clock (whose small corrections the differences would amplify). A sample is
        reached one period after its sample time, as a first-order hold reaches it: with one command
        per step (T = Δt) and arrivals on the twin's own time the target is the sample itself, bit
        for bit. With arrivals on the wall clock (``on_wall``) it is always the parabola one period
        before ``t1``: a command applied a step later or earlier than its arrival (a backlog taken in
        one go, a step a command ran ahead of the clock) then still gets its sample clock's value
        at ``t1``, where the sample itself made every such step a jump of one sample (1 kHz bare
        streams: 40 m/s² command accelerations against 0.3 m/s² in the law)."""
        dt1 = 0.0 if T == self.dt and not on_wall else t1 - self._grid - tau
        _predict_lines(np.ascontiguousarray(idx, dtype=np.int64), np.ascontiguousarray(lengths, dtype=np.float64),
                       float(tau), bool(stamped), float(self._grid), float(T), float(dt1), self.hist_L, self.hist_t,
                       self.hist_n, self.hist_stamped, self.base, self.rate, self.acc)

    def _apply(self, topic, idx, lengths, rates, t_ref, now, stamp, arrival: float | None = None) -> None:
        if self.hold != "step":
            T, tau = self._period(topic, stamp, now, arrival, idx, lengths)
            cur, vcur = self._in_force(now)
        else:
            T, vcur = 0.0, None
            cur = self._in_force(now)[0] if (self.trajectory is not None or self._held is not None
                                             or self.timed_out(now)) else None
        if cur is not None:
            self._leave_trajectory_and_timeout(idx, now, cur)
        self.fade_t[idx] = math.inf
        if rates is not None:                 # the commanded line L + v (t − stamp)
            self.base[idx] = lengths
            self.rate[idx] = rates
            self.acc[idx] = 0.0
            self.t_ref[idx] = t_ref
        elif self.hold == "smooth":           # the predicted line, reached at the segment's end
            t1 = now + T
            self._predict(idx, lengths, tau, stamp > 0, T, t1, arrival is not None)
            self.t_ref[idx] = t1
            # the parabola carries the line over up to _MAX_LOST lost samples, then it goes straight on
            self.acc_end[idx] = t1 + min(_MAX_LOST * self._grid, STALL_GRACE)
            # a late sample, a stalled transport: the line goes on for a while (at least STALL_GRACE)
            # before its rate fades to rest, so a stall of a few tens of ms is not a stop and go
            self.fade_t[idx] = t1 + max(T, STALL_GRACE)
            self.fade_T[idx] = max(T, STALL_GRACE)
        else:
            self.base[idx] = lengths
            self.rate[idx] = 0.0
            self.acc[idx] = 0.0
            self.t_ref[idx] = t_ref
        if T > 0.0:
            self.seg_t0[idx] = now
            # a line stamped ahead of the twin's time (a controller whose clock runs ahead, commands
            # that arrive early) is joined at its stamp, where it is what it says: joined one period
            # from now, a line of a curved motion is taken far from its stamp, where it is wrong by
            # L''(s − t)²/2 — measured: a player's estimate 0.5 s ahead made 1.5 cm kinks in one step
            self.seg_end[idx] = t_ref if rates is not None and stamp > now + T else now + T
            self.seg_p0[idx] = cur[idx]
            self.seg_v0[idx] = vcur[idx]
            cubic = rates is not None or self.hold == "smooth"
            self.seg_cubic[idx] = cubic
            self.last_period = T
            if cubic and self.max_accel < math.inf:
                _bound_joins(np.ascontiguousarray(idx, dtype=np.int64), float(now), self.max_accel, MAX_HOLD_PERIOD,
                             self.base, self.rate, self.acc, self.t_ref, self.seg_p0, self.seg_v0, self.seg_end,
                             self.fade_t)
        else:
            self.seg_end[idx] = -math.inf
        self._mark_accepted(now, stamp)

    def _mark_accepted(self, now: float, stamp: float) -> None:
        self.accepted += 1
        self.last_accept = now
        if stamp > 0:
            self.last_stamp = stamp
        self.newest_stamp = stamp

    def warmup(self) -> None:
        """Compile (or load) the kernels that applying and evaluating commands call, on scratch
        copies: the first command must not wait for numba (seconds with a cold cache)."""
        na = len(self.names)
        z, zi = np.zeros(na), np.zeros(na, dtype=np.int64)
        _evaluate_lines(0.0, z, z, z, z, z, z.copy() + np.inf, z + 1.0, z, z - np.inf, z, z, np.zeros(na, dtype=bool),
                        np.zeros(na), np.zeros(na))
        _predict_lines(np.arange(na, dtype=np.int64), z, 0.0, False, self.dt, self.dt, 0.0, np.zeros((na, 2)),
                       np.zeros((na, 2)), zi.copy(), np.zeros(na, dtype=bool), np.zeros(na), np.zeros(na), np.zeros(na))
        _interval_stats(np.full(3, self.dt))
        _grid_steps(self.dt, self.dt)
        _arrival_slope(np.arange(4.0), np.arange(4.0), 3, 3)
        _arrival_envelope(np.arange(4.0), np.arange(4.0), 3, 3, np.zeros(4, dtype=np.int64))
        _bound_joins(np.arange(na, dtype=np.int64), 0.0, 1.0, MAX_HOLD_PERIOD, z, z, np.zeros(na), z, z, z,
                     z + self.dt, np.zeros(na))

    # -- evaluation ----------------------------------------------------------------------------
    def _lines(self, t: float) -> None:
        """Lengths and rates of the lines and hold segments at ``t`` into ``_out``, ``_out_rate``."""
        _evaluate_lines(t, self.base, self.rate, self.acc, self.acc_end, self.t_ref, self.fade_t, self.fade_T,
                        self.seg_t0, self.seg_end, self.seg_p0, self.seg_v0, self.seg_cubic, self._out, self._out_rate)

    def _direct(self, t: float) -> np.ndarray:
        """Commanded lengths at ``t`` (m, a reused buffer): the lines, the hold segments, the trajectory."""
        self._lines(t)
        out = self._out
        if self.trajectory is not None:
            out[self.trajectory.idx] = self.trajectory.at(t)
        return out

    def _direct_rate(self, t: float) -> np.ndarray:
        """Commanded rates (m/s) at ``t`` (a new array)."""
        self._lines(t)
        v = self._out_rate.copy()
        if self.trajectory is not None:
            v[self.trajectory.idx] = self.trajectory.at(t, rate=True)
        return v

    def _stopping(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lengths and rates at ``t`` of the commands stopping from the timeout on (uniform
        deceleration over :data:`TIMEOUT_STOP`), and where they come to rest."""
        # a ramp to rest must be over after ramp_time: the stop takes no longer than the ramp
        stop = TIMEOUT_STOP if self.behaviour == "hold" else min(TIMEOUT_STOP, self.ramp_time)
        ts = min(max(t - self._t_hold, 0.0), stop)
        v = self._held_v
        return (self._held + v * (ts - ts * ts / (2.0 * stop)), v * (1.0 - ts / stop), self._held + 0.5 * stop * v)

    def _held_value(self, t: float) -> np.ndarray:
        """After the timeout: the commands stop smoothly (``hold``), then (``ramp_to_rest``) ramp
        from where they stopped to the start lengths (C² smoothstep over ``ramp_time``)."""
        length, _, final = self._stopping(t)
        if self.behaviour == "hold":
            return length
        s = min(max((t - self._t_hold) / self.ramp_time, 0.0), 1.0)
        w = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)     # C² smoothstep
        return length + w * (self.rest - final)

    def _held_rate(self, t: float) -> np.ndarray:
        _, rate, final = self._stopping(t)
        if self.behaviour == "hold":
            return rate
        s = min(max((t - self._t_hold) / self.ramp_time, 0.0), 1.0)
        dw = 30.0 * s * s * (1.0 - s) ** 2 / self.ramp_time
        return rate + dw * (self.rest - final)

    def _quiet_since(self) -> float:
        """Time from which the timeout counts: the newest command, or the end of a trajectory."""
        tr = self.trajectory
        return self.last_accept if tr is None else max(self.last_accept, float(tr.times[-1]))

    def timed_out(self, t: float) -> bool:
        return self.last_accept > -math.inf and t - self._quiet_since() > self.timeout

    def lengths_at(self, t: float) -> np.ndarray:
        """Commanded lengths (m) at simulated time ``t``, clamped to the stroke (a view: copy it)."""
        if self.timed_out(t):
            if self._held is None:
                self._t_hold = self._quiet_since() + self.timeout
                self._held = np.clip(self._direct(self._t_hold), self.stroke[:, 0], self.stroke[:, 1]).copy()
                self._held_v[:] = self._direct_rate(self._t_hold)
            self._out[:] = self._held_value(t)
            return self._out
        out = self._direct(t)
        np.clip(out, self.stroke[:, 0], self.stroke[:, 1], out=out)
        return out
