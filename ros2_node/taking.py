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

# most messages one callback takes straight from a subscription's history (beyond its depth only
# what arrived meanwhile; a bound, so that a flood cannot hold the callback)
TAKE_MAX = 64


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
    handle, msg_type, raw = subscription.handle, subscription.msg_type, subscription.raw
    out = []
    for _ in range(limit):
        with handle:
            taken = handle.take_message(msg_type, raw)
        if taken is None:
            break
        out.append(taken[0])
    return out
