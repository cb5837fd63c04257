"""A recording's commands through a twin in lockstep: the loop ``flexmb replay`` and ``flexmb
calibrate`` share (:mod:`flexmb_io.twin`'s timing rule).

1. before the step from ``t_n``, apply every recorded command logged at ≤ ``t_n`` (ns), in file
   order;
2. step (an offline run's last step is shortened to land on its ``until``, as ``flexmb run`` does);
3. hand the new time (ns) to the caller, who samples what it needs.

No ROS is needed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

from .. import topics as T

MAX_FAILED_STEPS = 10          # consecutive steps that do not advance before giving up


@dataclass
class LockstepResult:
    """What the loop did: steps, commands applied and rejected, and why it stopped early."""

    steps: int = 0
    failed_steps: int = 0
    commands_applied: int = 0
    commands_rejected: int = 0
    rejections: list[str] = field(default_factory=list)
    failure: str = ""
    t_end: float = 0.0


def input_kinds(node_name: str, namespace: str = "/") -> dict[str, str]:
    """Resolved command topic (of a node ``node_name`` in ``namespace``) → the ``topic_kind`` of
    :func:`flexmb_io.twin.apply_message`."""
    return {T.Topic(name, "", "in", "").resolved(node_name, namespace): kind for name, kind in T.KINDS.items()}


def ns(t: float) -> int:
    """Seconds → integer nanoseconds (the bag's log times)."""
    return int(round(t * 1e9))


def run_lockstep(runner, commands: list[tuple[int, str, str, Any, float | None]], *, last_ns: int,
                 until: float | None,
                 at: Callable[[int], bool]) -> LockstepResult:
    """Step ``runner`` (started) on ``commands`` until ``last_ns`` or ``until``.

    Parameters
    ----------
    runner : flexmb_io.twin.TwinRunner
        A started runner (its initial state is time ``runner.t``).
    commands
        ``(log time ns, topic, topic kind, message, arrival)`` sorted by time (file order within one
        time); the message is a decoded message or plain dicts; ``arrival`` is
        :attr:`flexmb_io.bag.reader.BagMessage.arrival` (a live node's wall-clock arrival, s of twin
        time, or None).
    last_ns
        Stop once the twin's time reaches this (ns).
    until
        An offline run's end time (s): the last step is shortened to land on it; None for node bags.
    at
        Called with the time (ns) of the initial state and of every advanced step; returns False to
        stop (nothing more is needed).
    """
    from ..twin import apply_message

    res = LockstepResult()
    dt = runner.dt
    i, failed_in_a_row = 0, 0
    more = at(ns(runner.t))
    while True:
        t = runner.t
        t_ns = ns(t)
        while i < len(commands) and commands[i][0] <= t_ns:
            _, topic, kind, msg, arrival = commands[i]
            i += 1
            r = apply_message(runner, kind, topic, msg, arrival)
            res.commands_applied += 1
            if r is not None:
                res.commands_rejected += 1
                if len(res.rejections) < 20:
                    res.rejections.append(f"t = {t:.9g} s: {r}")
        if t_ns >= last_ns or not more:
            break
        if until is not None:
            if not t < until - 1e-12 * max(1.0, until):
                break
            runner.dt = min(dt, until - t)         # flexmb run shortens the last step the same way
        outcome = runner.step()
        runner.dt = dt
        res.steps += 1
        if not outcome.advanced:
            res.failed_steps += 1
            failed_in_a_row += 1
            if failed_in_a_row >= MAX_FAILED_STEPS:
                res.failure = f"{failed_in_a_row} replay steps in a row failed at t = {t:.9g} s: {outcome.message}"
                break
            continue
        failed_in_a_row = 0
        more = at(ns(runner.t))
    res.t_end = runner.t
    return res
