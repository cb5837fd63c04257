"""Taking what waits in a subscription's history, outside the executor's events queue.

rclpy 9.1.2's ``EventsExecutor`` queues one entry (≈ 140 bytes) per message Fast DDS announces;
an entry takes one message and runs its callback, and is dropped without one only when the
history is empty by then. A process slower than its input (an overloaded machine) therefore keeps
the entries of every message the keep-last history overwrote: they pile up, one per message it
never took (measured: +1.44 MB in 15 s, a 3 ms callback at 1 kHz; ``benchmarks/node_overload_rss.py``).
Taking the history empty in the callback leaves those entries nothing to take, so the executor
drops them (the node's ``_take_commands``, the player's status callback).
"""

from __future__ import annotations

import time

# most messages one callback takes straight from a subscription's history (beyond its depth only
# what arrived meanwhile; a bound, so that a flood cannot hold the callback)
TAKE_MAX = 64


def _take(subscription, limit: int) -> list:
    """``(message, message info)`` of what waits in ``subscription``'s history, oldest first, at most
    ``limit``."""
    handle, msg_type, raw = subscription.handle, subscription.msg_type, subscription.raw
    out = []
    for _ in range(limit):
        with handle:
            taken = handle.take_message(msg_type, raw)
        if taken is None:
            break
        out.append(taken)
    return out


def take_waiting(subscription, limit: int = TAKE_MAX) -> list:
    """The messages waiting in ``subscription``'s history, oldest first, at most ``limit``.

    Parameters
    ----------
    subscription : rclpy.subscription.Subscription
        A subscription whose messages are deserialized (not ``raw``) or raw bytes (``raw``).
    limit : int
        Most messages taken.

    Returns
    -------
    list
        The messages (their type, or ``bytes`` for a raw subscription).
    """
    return [msg for msg, _ in _take(subscription, limit)]


def take_waiting_received(subscription, limit: int = TAKE_MAX) -> list:
    """As :func:`take_waiting`, each message with the time Fast DDS received it, as
    ``(message, reception)``: ``time.perf_counter()`` seconds (the middleware stamps it on the
    system clock; mapped here by the two clocks' offset now). A reception after now (the system
    clock stepped) is taken as now.

    The reception, not the take, is a command's arrival: a backlog that waited in the history for
    an executor busy elsewhere was taken in one go, at one time, where its samples had come one
    period apart (measured: 5 commands of a 1 kHz stream taken together after a 5 ms stall, then
    applied over 6 steps; as arrivals they made a 1 kHz stream's sample clock wobble)."""
    out = _take(subscription, limit)
    if not out:
        return out
    now_perf, now_ns = time.perf_counter(), time.time_ns()
    return [(msg, now_perf - max(0, now_ns - info["received_timestamp"]) * 1e-9) for msg, info in out]
