"""The twin's time loop on a thread of its own (no ROS here: the node wires it to rclpy).

:class:`Stepper` keeps the :class:`~flexmb_io.twin.TwinRunner`'s time: its thread runs the steps
no command asked for, calling the numba step (which releases the GIL, so the executor and the
publisher run meanwhile), and copies what the publisher needs into a preallocated ring of
:class:`Snapshot` slots. Nothing in the loop builds a message or writes a file; the publisher
thread turns due snapshots into messages. Commands are validated and applied by the thread that
receives them (:meth:`Stepper.submit`, the executor), which also runs the step that uses them when
the pacing allows; one lock makes a command and a step exclude each other, so a command applied
while the twin is at ``t_n`` acts on the step ``t_n → t_n + Δt`` — the time it is recorded with,
which a replay re-applies it at.

Pacing (``realtime``). State ``n`` stands for the wall time ``t0 + nΔt``. The step to state
``n + 1`` must end by its deadline ``t0 + (n+1)Δt``. Without a command it starts at the latest
safe moment, ``margin`` before its deadline; a command starts it at once — on the thread that
received the command — as long as the twin is then at most :data:`COMMAND_LEAD` steps ahead of the
wall clock, so a command is answered within one step's compute time instead of waiting for the
next tick (a command that finds the twin that far ahead waits for the next step: see
:data:`COMMAND_LEAD`). A step that ends after its deadline is a deadline miss;
one that ends more than ``max_lag`` late re-anchors the clock (an overrun) instead of bursting.
``lockstep``: one step per command, as soon as it arrives.

Holding (:meth:`Stepper.hold`: the node's ``~/pause`` and lifecycle deactivation) stops the steps
with the state kept; commands are still applied (a lockstep command then owes no step), and
:meth:`Stepper.step_n` takes N steps at once (``~/step``). :meth:`Stepper.release` re-anchors the
wall clock at the state in hand, so a held twin does not count the pause as lateness.
:meth:`Stepper.reset` puts the runner back to its initial state (``~/reset``).

``/clock`` goes out at its own decimation (``clock_every`` steps) as a light ``("clock", t)`` event
in the outbox, apart from the state snapshots.
"""

from __future__ import annotations

import collections
import ctypes
import math
import os
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from flexmb_core.model.workspace import State

from .commands import PUBLISHER_STALLED
from .twin import TwinRunner, apply_message

_PR_SET_TIMERSLACK = 29
# steps a command-triggered step may put the twin ahead of the wall clock beyond where the idle steps
# keep it: an idle step runs late in its period (step_margin before the deadline), so a command
# arriving after it would otherwise wait for the next period; within the lead it is answered at once
# and the idle steps wait for the clock instead. A step_margin of more than Δt keeps the twin that
# many steps ahead of the wall clock (a buffer against late wake-ups); the commands' lead adds to it.
# A command stream at the step rate takes one step per command, and an idle step that fills a gap in
# it (a late command) puts the twin a step further ahead of the stream for good, so the twin soon
# runs at this lead: the steps that commands run then end up to the lead minus a period before their
# deadline, and a command that finds the twin at the lead waits for the next step — the next
# command's, or the idle step at its usual time. Never for the first moment the lead allows: that
# kept the twin at the lead for good, every later command waiting for the clock too. Measured
# (docs/benchmarks/node_ab_lead.md: bar legs and the demo's frame legs, 1 kHz stamped commands, 3
# interleaved 20 s rounds, medians, bars / frame legs): that earlier rule (lead 2) made 16 359 / 14 926 of
# ~20 400 commands wait, missed 28 / 26 deadlines, latency p50 0.94 / 0.97 ms, p99 5.2 / 3.3 ms, CPU
# beyond the solver 61 % of a core; this rule with a lead of 2: 314 / 362 waited, p50 0.70 / 0.71 ms,
# but 80 / 83 missed (the steps that commands run at the lead end as little as one period before
# their deadline); with 4: 11 / 7 waited, 6 / 9 missed, p50 0.69 / 0.72 ms, p99 2.8 / 3.0 ms, 51–52 %.
# The price: a command acts on the twin's time, up to this many steps ahead of its arrival.
COMMAND_LEAD = 4
# s the stepping thread blocks before each step while it is behind the wall clock: a twin that
# cannot keep up (and on SCHED_FIFO would never leave its core) still lets the executor, the
# publisher and the rest of the machine run (measured: a 50 kHz overloaded twin starved DDS
# discovery of a client on the 2-core machine)
BEHIND_PAUSE = 1.0e-4
# The automatic step margin (``StepperConfig.margin_auto``): an idle step starts early enough for
# the step's own p99.9 wall time over the last ``window`` steps plus this headroom (s: the host's
# p99 wake-up lateness, 0.17 ms measured, docs/benchmarks/node.md), never less than the configured
# margin and at most AUTO_MARGIN_STEPS Δt; re-evaluated every AUTO_MARGIN_EVERY steps. Measured
# (1 kHz node and player, 3 interleaved 20 s rounds, medians, docs/benchmarks/node_ab_frame1.md and
# node_ab_bars.md): the 1-element frame-leg twin, whose tangent refreshes take 0.4–0.9 ms, missed
# 2 430 of ~21 300 deadlines with the fixed 0.4 ms and 206 with this (0.60–0.94 ms in force); the
# bar-leg twin 297 and 180 (0.40–0.58 ms); the same command→state latency (README "Deadlines and
# the host"). An earlier pair of runs gave 754 / 140 and 683 / 44.
AUTO_MARGIN_HEADROOM = 2.0e-4
AUTO_MARGIN_STEPS = 4
AUTO_MARGIN_EVERY = 250


def auto_margin(step_p999: float, floor: float, dt: float) -> float:
    """The idle steps' margin (s) before their deadline for a step whose recent p99.9 wall time is
    ``step_p999`` (s): that plus :data:`AUTO_MARGIN_HEADROOM`, within [``floor``,
    max(``floor``, :data:`AUTO_MARGIN_STEPS` × ``dt``)]."""
    return min(max(floor, step_p999 + AUTO_MARGIN_HEADROOM), max(floor, AUTO_MARGIN_STEPS * dt))


def timer_slack(ns: int) -> bool:
    """Shorten this thread's timer slack (Linux default 50 µs of lateness on every sleep)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(ns), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


# SCHED_FIFO priority of rt_priority = -1 ("where the OS allows it"): above the normal threads,
# well below the kernel's own real-time threads (50 and up on PREEMPT_RT kernels)
AUTO_RT_PRIORITY = 20


def raise_to_fifo(priority: int) -> tuple[int, os.sched_param] | None:
    """Put the calling thread on SCHED_FIFO ``priority``. Returns its scheduling before (for
    :func:`restore_scheduling`), or None where the OS refuses (no CAP_SYS_NICE or rtprio limit)."""
    try:
        before = (os.sched_getscheduler(0), os.sched_getparam(0))
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError):
        return None
    return before


def restore_scheduling(before: tuple[int, os.sched_param] | None) -> None:
    """Put the calling thread back on the scheduling :func:`raise_to_fifo` returned."""
    if before is not None:
        try:
            os.sched_setscheduler(0, *before)
        except OSError:
            pass


def fifo_priority_in_force() -> int:
    """The calling thread's SCHED_FIFO priority, 0 when it runs on another policy."""
    try:
        return os.sched_getparam(0).sched_priority if os.sched_getscheduler(0) == os.SCHED_FIFO else 0
    except (OSError, AttributeError):
        return 0


def apply_thread_scheduling(cpus: tuple[int, ...], rt_priority: int) -> tuple[list[str], list[str]]:
    """Pin the calling thread to ``cpus`` and give it SCHED_FIFO ``rt_priority`` (0: normal
    scheduling; −1: :data:`AUTO_RT_PRIORITY` if the OS allows it). Returns (warnings, notes): what
    the OS refused of an explicit request, and what it refused of the automatic one."""
    warnings, notes = [], []
    if cpus:
        try:
            os.sched_setaffinity(0, set(cpus))
        except (OSError, ValueError) as exc:
            warnings.append(f"cpu_affinity {list(cpus)} not applied ({exc}); the step thread runs on any CPU")
    if rt_priority != 0:
        prio = AUTO_RT_PRIORITY if rt_priority < 0 else rt_priority
        if raise_to_fifo(prio) is not None:
            notes.append(f"stepping thread on SCHED_FIFO priority {prio}")
        else:
            text = (f"rt_priority {prio} (SCHED_FIFO) not applied: the OS refused it (it needs CAP_SYS_NICE or an "
                    "rtprio limit, ulimit -r); the stepping thread keeps the normal scheduler")
            (notes if rt_priority < 0 else warnings).append(text)
    return warnings, notes


# The kernel's PM QoS interface for the CPUs' idle states: while a process holds this file open with a
# latency (µs, int32) written to it, cpuidle keeps every CPU out of idle states that take longer to
# leave (0: the CPUs poll when idle, never halt) — the setting cyclictest and real-time stacks use.
CPU_DMA_LATENCY = "/dev/cpu_dma_latency"


class IdleLatencyRequest:
    """A PM QoS request on the CPUs' idle-state exit latency (``cpu_dma_latency``), held until
    :meth:`release`.

    A CPU that wakes from a deep idle state (on a virtual machine: a halted vCPU the hypervisor
    descheduled) starts the work late and with cold caches. Measured on this 2-core KVM guest
    (cpuidle haltpoll, 2026-11-29): a 1 kHz SCHED_FIFO wake-up p50 / p99 17 / 47–52 µs against
    31–41 / 83–99 µs, the node's command→state latency p50 −0.08 ms — but the hypervisor then
    preempts the always-busy vCPUs in slices of milliseconds (wake-ups > 1 ms late 4–27 against 0–6
    in 40 s), which costs missed deadlines (README "Idle CPUs").

    Parameters
    ----------
    us : int
        Most exit latency allowed (µs, ≥ 0).
    path : str
        The PM QoS device (a test points it elsewhere).
    """

    def __init__(self, us: int, path: str = CPU_DMA_LATENCY):
        self.us, self.path = int(us), path
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> str:
        """Open the device and write the request; '' when in force, else why not (the device is
        missing or not writable: not Linux, no root or udev rule)."""
        try:
            fd = os.open(self.path, os.O_WRONLY)
        except OSError as exc:
            return f"{self.path}: {exc.strerror or exc}"
        try:
            os.write(fd, self.us.to_bytes(4, sys.byteorder, signed=True))
        except OSError as exc:
            os.close(fd)
            return f"{self.path}: {exc.strerror or exc}"
        self._fd = fd
        return ""

    def release(self) -> None:
        """Close the device: the kernel drops the request."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


# SCHED_FIFO priority of the node's other threads that take the GIL (the executor, which applies
# commands and runs their steps under the step lock, and the publisher) with ``rt_threads: node``,
# this far below the stepping thread's (never below 1). A thread on the normal scheduler that holds
# the GIL or the step lock when the kernel preempts it for another process holds up the stepping
# thread for the rest of a time slice, whatever the stepping thread's own priority: measured with
# probes (2026-11-29, bar legs at 1 kHz), a command's step on the executor took 4.8 ms instead of
# 0.1 while a SCHED_FIFO thread of the same process that needs the GIL woke 3.9 ms late and one that
# does not was on time, and a burst of missed deadlines followed. On SCHED_FIFO a thread is
# preempted only by one of higher priority; the stepping thread, which preempts them, then waits for
# the GIL at most the switch interval. (The middleware's own threads never take the GIL and keep
# the normal scheduler.) Measured, interleaved (docs/benchmarks/node_ab_rt_threads*.md, medians):
# with two busy loops on the machine 251 against 389 missed deadlines in 30 s, in-node latency p99
# 1.4 against 6.3 ms; on an idle machine the same few misses (1 against 3) but a longer latency
# tail at the client (p99 2.2 against 1.6 ms; not pinned down: the client's threads, on the normal
# scheduler, yielding the cores to the node's is a likely cause), so it is not the default.
HELPER_PRIORITY_BELOW = 1


def helper_priority(stepping_priority: int) -> int:
    """SCHED_FIFO priority of the node's other GIL threads for a stepping thread on
    ``stepping_priority`` (0: the stepping thread runs on the normal scheduler, and so do they)."""
    return max(1, stepping_priority - HELPER_PRIORITY_BELOW) if stepping_priority > 0 else 0


@dataclass
class Snapshot:
    """One published step: the state after it and what the publisher needs to report it.

    ``state`` arrays are owned by the slot (copied into, never re-allocated)."""

    state: State
    seq: int = -1
    result: object = None            # StepResult of the step (None: the initial state)
    advanced: bool = False
    message: str = ""
    step_wall: float = 0.0           # s of wall time of the step
    end_wall: float = 0.0            # perf_counter at the step's end
    lateness: float = 0.0            # s past the deadline (> 0: missed), realtime only
    due: bool = False                # joint/actuator states, poses, /tf, /clock
    shape_due: bool = False
    on_command: bool = False         # first step that used a new command
    ack: bool = False                # lockstep: the acknowledgement of one command
    answered: bool = False           # the command's thread published the answer (status, joint states)
    answer: tuple | None = None      # what it published, serialized (recorded as it is), once answered
    wake: bool = False               # answered: something besides the answer is due (the caller wakes the publisher)
    cmd_recv_wall: float = 0.0       # perf_counter at the reception of the command it answers
    steps: int = 0
    failed_steps: int = 0
    flagged_steps: int = 0
    rejected: int = 0
    newest_stamp: float = 0.0

    @property
    def answered_only(self) -> bool:
        """Answered on the command's thread and nothing else due: the publisher only records it."""
        return self.answered and not (self.due or self.shape_due)


@dataclass
class StepperConfig:
    """Pacing of the stepping thread (node parameters of the same names)."""

    mode: str = "realtime"
    publish_every: int = 1           # steps between two state publications
    shape_every: int = 0             # steps between two shapes (0: never)
    clock_every: int = 0             # steps between two /clock publications (0: never)
    publish_on_command: bool = True
    max_lag: float = 0.1             # s
    margin: float = 4.0e-4           # s before a deadline at which an idle step starts (the least, when auto)
    margin_auto: bool = False        # fit the margin to the step's own recent wall time (auto_margin; widest first)
    duration: float = 0.0            # s of simulated time; 0: until stopped
    capacity: int = 256              # snapshot slots (the publisher may lag this many publications)
    cpu_affinity: tuple[int, ...] = ()
    rt_priority: int = -1
    window: int = 1000               # steps over which recent deadline misses are counted
    # events the outbox may hold for the publisher (≈ 65 s of a 1 kHz twin answering every step):
    # a publisher that stalls (a log sink that blocks, a disk that does not take the recording)
    # must not make the stepping thread's queue, and the node's memory, grow without bound
    outbox_limit: int = 1 << 16


@dataclass
class StepperStats:
    """Counters the publisher reads (written under the stepper's lock, by whichever thread steps;
    ``dropped_snapshots`` by the publisher)."""

    steps_advanced: int = 0
    deadline_misses: int = 0
    overruns: int = 0
    dropped_snapshots: int = 0       # publications the publisher fell too far behind to make
    stalled_drops: int = 0           # publications and /clock events not queued: the outbox was full
    recent_misses: int = 0           # deadline misses within the last ``window`` steps
    commands_waited: int = 0         # realtime commands that found the twin at its lead: no step of their own
    # misses whose step began after its deadline already: the thread came to it late (the host, or the
    # process, held the twin up: a burst of them follows a stall); the others began in time and
    # overran (the step itself, or a preemption within it, took longer than its slack)
    misses_started_late: int = 0

    @property
    def misses_overran(self) -> int:
        """Deadline misses whose step began in time and ended late."""
        return self.deadline_misses - self.misses_started_late

    @property
    def dropped_publications(self) -> int:
        """Publications never made: lapped in the ring, or not queued into a full outbox."""
        return self.dropped_snapshots + self.stalled_drops


class Samples:
    """The newest ``capacity`` values of a per-step quantity, in a buffer allocated once (a node
    runs for hours: a growing list would allocate at every step), and the count and sum of all.

    :meth:`percentiles` allocates nothing either: it works in a scratch buffer allocated once.
    Measured (issue 15, ``docs/benchmarks/node_rss_soak.md``): ``np.percentile`` of ``sign *
    buffer`` made two temporaries as large as the filled part of the buffer, once a second for
    ``/diagnostics``; as the buffer filled, glibc served the ever larger temporaries from the
    publisher thread's malloc arena, which grew by ≈ 1 MB a minute and never gave the memory back
    (``malloc_trim`` freed none of it), and each call held the GIL for milliseconds over 4 MB.
    Periodic reports therefore ask for the ``last`` values only (``/diagnostics``: the last
    second's window); the whole buffer is read for the run's summary."""

    def __init__(self, capacity: int = 1 << 19):
        # written through now, so its pages are resident from the start: an untouched buffer
        # (np.empty/np.zeros) grows the RSS by 8 kB/s per 1 kHz quantity until it is full (8.7 min),
        # which a soak reads as a leak
        self._buf = np.full(capacity, 0.0)
        self._scratch = np.empty(capacity)
        self._scratch_lock = threading.Lock()    # two reporting threads may ask at once
        self.count = 0
        self.total = 0.0

    def add(self, x: float) -> None:
        self._buf[self.count % self._buf.size] = x
        self.count += 1
        self.total += x

    def percentiles(self, qs=(50, 99), sign: float = 1.0, last: int | None = None) -> dict:
        """Percentiles of ``sign`` × the newest ``last`` values (default: all the buffer holds), their
        max, and how many they are."""
        size = self._buf.size
        n = min(self.count, size) if last is None else min(self.count, size, max(0, int(last)))
        if not n:
            return {f"p{q}": 0.0 for q in qs} | {"max": 0.0, "count": 0}
        with self._scratch_lock:
            a = self._scratch[:n]
            end = self.count % size             # one past the newest value
            head = min(n, end)                  # the newest values before the wrap-around
            np.multiply(self._buf[end - head:end], sign, out=a[n - head:])
            if n > head:                        # the older ones, at the end of the ring
                np.multiply(self._buf[size - (n - head):], sign, out=a[:n - head])
            top = float(a.max())
            # in place: np.percentile would otherwise copy the n values (overwrite_input)
            values = np.percentile(a, qs, overwrite_input=True)
        return {f"p{q}": float(v) for q, v in zip(qs, values)} | {"max": top, "count": int(n)}


class Series:
    """Every value of a per-step quantity, appended in amortized O(1) to a float64 buffer that
    doubles when full: 8 bytes per value for as long as the run lasts (a Python list of floats
    takes 32, and a 1 kHz client keeps three of them). ``width``: each value is a row of that many
    floats (``add`` takes a sequence)."""

    def __init__(self, capacity: int = 1 << 12, width: int | None = None):
        self._buf = np.empty(capacity if width is None else (capacity, width))
        self.count = 0

    def add(self, x) -> None:
        if self.count == self._buf.shape[0]:
            self._buf = np.concatenate([self._buf, np.empty_like(self._buf)])
        self._buf[self.count] = x
        self.count += 1

    def __len__(self) -> int:
        return self.count

    @property
    def values(self) -> np.ndarray:
        """The values so far, shape (count,) or (count, width) (a view: copy it to keep it past
        the next add)."""
        return self._buf[:self.count]


class Stepper:
    """The stepping thread of one twin (see the module).

    Parameters
    ----------
    runner : a started :class:`TwinRunner`; from :meth:`start` on it is touched only under the
        stepper's lock (:meth:`submit` and the stepping thread).
    config : pacing and publication decimation.
    notify : called (from the thread that queued it) after a snapshot or command event is queued.
    """

    def __init__(self, runner: TwinRunner, config: StepperConfig, notify):
        self.runner = runner
        self.cfg = config
        self.dt = runner.dt
        self._notify = notify
        # ("cmd", topic, kind, msg, t_applied, rejection, recv_wall, tag, arrival) | ("out", slot, seq) |
        # ("clock", t), in the order things happened (appended under the lock)
        self.outbox: collections.deque = collections.deque()
        self._lock = threading.Lock()         # a command application and a step exclude each other
        self._pending = 0                     # lockstep: commands applied that still owe their step
        self.margin = config.margin           # s, in force (auto_margin sets it when margin_auto)
        if config.margin_auto:
            # no step measured yet: the widest margin of the rule until AUTO_MARGIN_EVERY steps are.
            # The first steps are the slowest (first calls, cold caches, the client connecting):
            # measured, 5 interleaved pairs of `flexmb demo` (bar legs, 1-element frame legs), the
            # first 300 steps missed 2–23 deadlines per run starting at the configured 0.4 ms, 0–1
            # starting at this
            self.margin = auto_margin(math.inf, config.margin, self.dt)
        self.wake = threading.Event()
        self._ready = threading.Event()
        self._t0 = 0.0                        # wall time of state 0 (perf_counter; re-anchored on overruns)
        self._n = 0                           # states since t0
        self._running = False                 # the realtime loop has set t0
        self._held = False                    # no steps (paused or inactive); commands still apply
        self.stop_event = threading.Event()
        self.finished = threading.Event()
        st = runner.sim.state
        self.slots = [Snapshot(st.copy()) for _ in range(config.capacity)]
        self._seq = 0
        self.stats = StepperStats()
        self.step_walls = Samples()
        self.iterations = Samples(1 << 16)    # Newton iterations per step (the newest 65 536 steps)
        self.lateness = Samples()
        self._miss_ring = np.zeros(config.window, dtype=np.int8)
        self._new_command = False
        self._cmd_recv_wall = 0.0
        self.warnings: list[str] = []        # what the OS refused of an explicit request
        self.notes: list[str] = []           # how the stepping thread is scheduled
        self.fifo_priority = 0               # the stepping thread's SCHED_FIFO priority once started (0: none)
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name="flexmb-step", daemon=True)

    # -- lifecycle ------------------------------------------------------------------------------
    def start(self) -> None:
        """Queue the initial state, start the thread; returns once its scheduling is set (the
        warnings of what the OS refused are in :attr:`warnings` then)."""
        self._initial_events()
        self._thread.start()
        self._ready.wait(5.0)

    def _initial_events(self) -> None:
        """The state in hand (at start, on hold, after a reset) queued for publication, with its
        /clock."""
        self._snapshot(self.runner.sim.last, False, "", 0.0, 0.0, True, True, False, False)
        if self.cfg.clock_every:
            self.outbox.append(("clock", self.runner.t))

    @property
    def held(self) -> bool:
        return self._held

    def hold(self) -> None:
        """No more steps from now on (the one under way ends first); the state is kept and
        published (the decimation may have skipped it), with its /clock."""
        with self._lock:
            self._held = True
            self._pending = 0
            self._initial_events()
        self.wake.set()

    def release(self) -> None:
        """Step again, the wall clock re-anchored at the state in hand (a hold is no lateness)."""
        with self._lock:
            self._held = False
            self._pending = 0
            self._t0 = time.perf_counter() - self._n * self.dt
        self.wake.set()

    def step_n(self, n: int) -> tuple[int, str]:
        """``n`` steps at once on the calling thread, unpaced (lockstep); the last one's state is
        published (status and joint states). Returns (steps that advanced, the last failure's
        message or ''). Stops early at ``duration``."""
        advanced, message = 0, ""
        with self._lock:
            for i in range(n):
                if self._done():
                    message = message or f"duration {self.cfg.duration:g} s reached"
                    break
                before = self.stats.steps_advanced
                _, snap = self._step(math.inf, ack=i == n - 1, due=i == n - 1)
                self._n += 1
                if self.stats.steps_advanced > before:
                    advanced += 1
                elif snap is not None and snap.message:
                    message = snap.message
        self._notify()
        return advanced, message

    def reset(self) -> None:
        """The runner back to its initial state (:meth:`TwinRunner.reset`), the wall clock
        re-anchored there and the initial state queued for publication."""
        with self._lock:
            self.runner.reset()
            self._n = 0
            self._pending = 0
            self._new_command = False
            self._t0 = time.perf_counter()
            self._initial_events()
        self.wake.set()

    def stop(self, timeout: float = 5.0) -> None:
        self.stop_event.set()
        self.wake.set()
        self._thread.join(timeout)

    def submit(self, topic: str, kind: str, msg, recv_wall: float, tag=None, steps: int = 1) -> Snapshot | None:
        """A command message arrived (any thread): validate and apply it at the twin's current
        time and queue its event (``tag`` comes back with it in :attr:`outbox`).

        Realtime: when the twin is not a step ahead of the wall clock, the step that uses the
        command runs right here, on the receiving thread — a command's whole path (apply, step,
        answer) then crosses no thread, which at 1 kHz costs less than waking the stepping thread
        and the publisher for each command — and its snapshot is returned: the caller answers it
        (it is queued as already answered: the publisher records it and publishes only what else
        is due; the caller wakes the publisher when ``snap.wake``, else the events wait for its next
        wake — a thread woken per command costs ~10–60 µs here, see :meth:`_step`). Otherwise (the
        twin is ahead) the command waits for the next step — the next command's, or the idle step
        at its usual time — and None is returned; lockstep: the stepping thread is woken for it.

        ``steps`` (realtime): the steps it may run here, as many as the wall clock allows (the last
        one's snapshot answered); 0: applied and recorded only. A backlog taken in one go is applied
        first and its newest command runs the steps of all (a step for each older command ran the
        twin on targets extrapolated from samples up to tens of ms old; none made the twin fall
        back on the idle steps, 22 → 304 missed deadlines in 21 500, 1 kHz stamped).
        Lockstep owes one step per command whatever ``steps`` says."""
        snap = None
        with self._lock:
            if len(self.outbox) >= self.cfg.outbox_limit:
                # the publisher has stalled: a command applied now could not be recorded, so it is
                # refused unapplied (counted; the node reports it once the publisher runs again)
                rejections = self.runner.counters.rejections
                rejections[PUBLISHER_STALLED] = rejections.get(PUBLISHER_STALLED, 0) + 1
                return None
            t_applied = self.runner.t
            arrival = self._arrival(recv_wall, t_applied)
            try:
                rejection = apply_message(self.runner, kind, topic, msg, arrival)
            except Exception as exc:            # a message the checks did not foresee: rejected whole
                rejection = f"{topic}: rejected: {type(exc).__name__}: {str(exc)[:200]}"
            if rejection is None:
                if not self._new_command:      # the answer's latency counts from the oldest it answers
                    self._cmd_recv_wall = recv_wall
                self._new_command = True
            self.outbox.append(("cmd", topic, kind, msg, t_applied, rejection, recv_wall, tag, arrival))
            realtime = self.cfg.mode == "realtime"
            if self._held or (steps <= 0 and realtime):      # applied; no step owed
                self._notify()
                return None
            if not realtime:
                self._pending += 1
            elif self._running and self._may_step():
                for i in range(steps):
                    if i and self._done():        # the duration ended within the backlog's steps
                        break
                    # the last step the clock allows answers (time only grows: a step allowed for
                    # state n + 2 now is allowed once state n + 1 is done)
                    final = i == steps - 1 or not self._may_step(ahead=1)
                    if final:
                        snap = self._step_paced(answered=True)
                        break
                    new, self._new_command = self._new_command, False   # the answer is the last state
                    self._step_paced(answered=False)
                    self._new_command = new
            else:
                # the twin is ahead of the wall clock: the command waits for the next step, the next
                # command's or the idle one (never an earlier one: COMMAND_LEAD); its event waits in
                # the outbox for that step's wake of the publisher
                self.stats.commands_waited += 1
        if not realtime:
            self.wake.set()      # the stepping thread steps for it and wakes the publisher when due
        return snap

    @property
    def _command_lead(self) -> int:
        """Steps ahead of the wall clock a command may take the twin: COMMAND_LEAD beyond the
        idle steps' lead (the margin in force, in whole steps)."""
        return COMMAND_LEAD + int(self.margin // self.dt)

    def _may_step(self, ahead: int = 0) -> bool:
        """Whether a command may run the step to state n + 1 + ``ahead`` now (under the lock): the
        twin is then at most the command lead ahead of the wall clock."""
        return not self._done() and (time.perf_counter()
                                     >= self._t0 + (self._n + 1 + ahead - self._command_lead) * self.dt)

    def _arrival(self, recv_wall: float, t_applied: float) -> float | None:
        """The twin time of a command received at ``recv_wall`` (perf_counter, s): the time whose
        deadline that wall time is, ``t + recv_wall − (t0 + nΔt)``, rounded to the ns that the
        recording keeps (its publish time) so that a replay applies the very same float; None
        (the twin's time, ``t_applied``) when not paced by the wall clock or when it rounds to the
        command's log time. Under the lock.

        A bare command's sample clock runs on these times (:meth:`CommandSchedule._period`): the
        twin's own time at acceptance stands still while the stepping thread is late."""
        if self.cfg.mode != "realtime" or not self._running or self._held:
            return None
        ns = max(0, round((t_applied + recv_wall - (self._t0 + self._n * self.dt)) * 1e9))
        return None if ns == round(t_applied * 1e9) else ns * 1e-9

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    # -- the loop ---------------------------------------------------------------------------------
    def _main(self) -> None:
        try:
            timer_slack(1000)
            if self.cfg.mode == "realtime":
                warnings, notes = apply_thread_scheduling(self.cfg.cpu_affinity, self.cfg.rt_priority)
                self.warnings += warnings
                self.notes += notes
                self.fifo_priority = fifo_priority_in_force()
            self._ready.set()
            if self.cfg.mode == "lockstep":
                self._loop_lockstep()
            else:
                self._loop_realtime()
        except BaseException as exc:           # reported by the node, never a silent dead thread
            self.error = exc
        finally:
            self._ready.set()
            self.finished.set()
            self._notify()

    def _done(self) -> bool:
        d = self.cfg.duration
        return self.stop_event.is_set() or (d > 0 and self.runner.t >= d - 0.5 * self.dt)

    def _update_margin(self) -> None:
        """The automatic margin from the recent steps' wall time (see :func:`auto_margin`)."""
        window = min(self.cfg.window, self.step_walls.count)
        if window < AUTO_MARGIN_EVERY:
            return
        p999 = self.step_walls.percentiles((99.9,), last=window)["p99.9"]
        self.margin = auto_margin(p999, self.cfg.margin, self.dt)

    def _loop_realtime(self) -> None:
        dt = self.dt
        wake, clock, lock = self.wake, time.perf_counter, self._lock
        last_update = 0
        with lock:
            self._t0 = clock()
            self._n = 0
            self._running = True
        while not self._done():
            if self._held:
                wake.clear()
                wake.wait(0.05)        # release() re-anchors the clock and wakes us
                continue
            # every AUTO_MARGIN_EVERY steps (and after a reset, which restarts the count)
            if self.cfg.margin_auto and not 0 <= self._n - last_update < AUTO_MARGIN_EVERY:
                last_update = self._n
                self._update_margin()
            margin = self.margin
            while True:
                wake.clear()
                n = self._n            # a command may have taken this step on its own thread
                # a command the lead kept from stepping (the twin was ahead) waits for this step
                # too, or for the next command's: see COMMAND_LEAD
                latest = self._t0 + (n + 1) * dt - margin
                now = clock()
                if now >= latest:
                    break
                if self.stop_event.is_set():
                    return
                if self._held:
                    break
                wake.wait(latest - now)
            if now >= latest + margin:        # behind: the deadline has passed already
                wake.wait(BEHIND_PAUSE)
            with lock:
                # else a command's thread stepped meanwhile, or the twin was held
                if self._n == n and not self._done() and not self._held:
                    self._step_paced(answered=False)

    def _step_paced(self, answered: bool) -> Snapshot | None:
        """The step to state n + 1 against its deadline t0 + (n+1)Δt (under the lock); re-anchors
        the schedule when far behind. Returns the snapshot it queued, if any."""
        deadline = self._t0 + (self._n + 1) * self.dt
        end, snap = self._step(deadline, answered=answered)
        self._n += 1
        if end - deadline > self.cfg.max_lag:    # far behind: re-anchor instead of bursting
            self.stats.overruns += 1
            self._t0 = end - self._n * self.dt
        return snap

    def _loop_lockstep(self) -> None:
        while not self._done():
            self.wake.clear()
            if not self._pending or self._held:
                self.wake.wait(0.05)
                continue
            with self._lock:
                self._pending -= 1
                self._step(math.inf, ack=True)
                self._n += 1

    # -- one step ----------------------------------------------------------------------------------
    def _step(self, deadline: float, ack: bool = False, answered: bool = False,
              due: bool = False) -> tuple[float, Snapshot | None]:
        """One step, its timing, and a snapshot when something is due; returns its end
        (perf_counter) and the snapshot queued, if any. ``answered``: the caller publishes the
        answer to the command itself (see :meth:`submit`); ``due``: publish this state whatever
        the decimation."""
        runner, cfg = self.runner, self.cfg
        attempts = runner.counters.steps
        a = time.perf_counter()
        outcome = runner.step()
        b = time.perf_counter()
        wall = b - a
        self.step_walls.add(wall)
        last = runner.sim.last
        if runner.counters.steps > attempts and last is not None:   # a stopped twin attempts none
            self.iterations.add(last.iterations)
        late = b - deadline if deadline != math.inf else 0.0
        missed = late > 0.0
        if deadline != math.inf:
            self.lateness.add(late)
            ring = self._miss_ring
            i = runner.counters.steps % ring.size
            self.stats.recent_misses += int(missed) - int(ring[i])
            ring[i] = missed
            if missed:
                self.stats.deadline_misses += 1
                if a > deadline:
                    self.stats.misses_started_late += 1
        if outcome.advanced:
            self.stats.steps_advanced += 1
        k = self.stats.steps_advanced
        on_command = cfg.publish_on_command and self._new_command and outcome.advanced
        due = due or k % cfg.publish_every == 0 or not outcome.advanced
        shape_due = bool(cfg.shape_every) and k % cfg.shape_every == 0
        message = outcome.message if (not outcome.converged or outcome.message) else ""
        snap = None
        if due or on_command or shape_due or ack:
            snap = self._snapshot(runner.sim.last, outcome.advanced, message, wall, late, due, shape_due, on_command,
                                  ack, answered and on_command)
            if on_command:
                self._new_command = False
        if cfg.clock_every and (k % cfg.clock_every == 0 or not outcome.advanced) and self._room():
            self.outbox.append(("clock", runner.t))
            if snap is not None and snap.answered:
                snap.wake = True                   # the answering caller wakes the publisher
            else:
                self._notify()
        return b, snap

    def _room(self) -> bool:
        """Whether the outbox takes one more state event; counts the one it cannot take."""
        if len(self.outbox) < self.cfg.outbox_limit:
            return True
        self.stats.stalled_drops += 1
        return False

    def _snapshot(self, result, advanced, message, wall, late, due, shape_due, on_command, ack,
                  answered: bool = False) -> Snapshot:
        runner = self.runner
        i = self._seq % len(self.slots)
        s = self.slots[i]
        s.state.assign(runner.sim.state)
        s.seq = self._seq
        s.result, s.advanced, s.message = result, advanced, message
        s.step_wall, s.end_wall, s.lateness = wall, time.perf_counter(), late
        s.due, s.shape_due, s.on_command, s.ack = due, shape_due, on_command, ack
        s.cmd_recv_wall = self._cmd_recv_wall if on_command else 0.0
        s.answered, s.answer = answered, None
        # Only what is published apart from the answer wakes the publisher: an answered state is
        # recorded at its next wake (at publish_rate). Measured on this 2-core VM, waking a thread
        # costs the waker ~10 µs and the process ~15 µs (Event.set at 1 kHz), and the publisher's
        # pass over one state more; at 1 kHz of commands that was ~1000 wakes/s for nothing live.
        s.wake = due or shape_due or ack or not answered
        c = runner.counters
        s.steps, s.failed_steps, s.flagged_steps = c.steps, c.failed_steps, c.flagged_steps
        s.rejected, s.newest_stamp = runner.rejected_commands, runner.newest_command_stamp
        if self._room():
            self.outbox.append(("out", i, self._seq))
        self._seq += 1
        if not answered:        # else the answering caller wakes the publisher once it is done, if due
            self._notify()
        return s
