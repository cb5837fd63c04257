"""The publisher thread gives way to a command in hand: between two messages it waits while the
executor handles a command, within its pass's budget, and never on any other thread."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

pytest.importorskip("rclpy")
from ros2_node.node import TwinNode  # noqa: E402


def _node(on_publisher_thread: bool, budget_s: float) -> SimpleNamespace:
    """What ``_yield_to_commands`` reads of a node whose executor is handling a command."""
    idle = threading.Event()               # cleared: the executor is handling a command
    return SimpleNamespace(_commands_idle=idle, _yield_until=time.perf_counter() + budget_s,
                           _publisher_ident=None, on_publisher_thread=on_publisher_thread)


def _yield_in_thread(node: SimpleNamespace) -> threading.Thread:
    def run():
        node._publisher_ident = threading.get_ident() if node.on_publisher_thread else -1
        TwinNode._yield_to_commands(node)
        node.returned_with_idle = node._commands_idle.is_set()
    t = threading.Thread(target=run)
    t.start()
    return t


def test_the_publisher_waits_until_the_command_is_handled():
    node = _node(True, budget_s=30.0)
    t = _yield_in_thread(node)
    t.join(0.05)
    assert t.is_alive()                    # still waiting: the command is in hand
    node._commands_idle.set()              # the executor's spin ends
    t.join(5.0)
    assert not t.is_alive() and node.returned_with_idle


def test_the_wait_ends_with_the_pass_budget_even_if_the_executor_never_rests():
    node = _node(True, budget_s=0.02)
    t = _yield_in_thread(node)
    t.join(5.0)
    assert not t.is_alive() and not node.returned_with_idle


def test_no_other_thread_waits():
    node = _node(False, budget_s=30.0)
    t = _yield_in_thread(node)
    t.join(5.0)
    assert not t.is_alive() and not node.returned_with_idle
