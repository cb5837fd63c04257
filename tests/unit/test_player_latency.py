"""The player's command→state latency counts every command a status answers: the twin echoes the
newest command a state includes (``TwinStatus.command_stamp``), so a status echoing stamp S answers
every command stamped up to S that is still waiting — a command taken with a newer one before one
step is answered, its latency counted, not left to expire as unanswered."""

from __future__ import annotations

import types

from flexmb_io.realtime import Series
from ros2_node.player import Player, TwinClock


def _player() -> Player:
    p = Player.__new__(Player)           # its bookkeeping only: no DDS
    p.sent, p.latencies, p.expired = {}, Series(), 0
    p.statuses = p.unconverged = 0
    p.answered_ns, p.sim_time, p.last_status, p.clock = -1, None, None, TwinClock()
    return p


def _status(ns: int, t: float):
    stamp = types.SimpleNamespace(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    return types.SimpleNamespace(converged=True, command_stamp=stamp, sim_time=t)


def test_a_status_answers_every_waiting_command_up_to_its_stamp():
    p = _player()
    p.sent.update({1_000_000: 10.0, 2_000_000: 10.001, 3_000_000: 10.002})
    p._read_status(_status(2_000_000, 0.002), 10.004)
    assert list(p.sent) == [3_000_000]                               # the newer one still waits
    assert sorted(p.latencies.values.round(6)) == [0.003, 0.004]     # both answered, the older later
    p._read_status(_status(3_000_000, 0.003), 10.005)
    assert not p.sent and p.latencies.count == 3 and p.statuses == 2


def test_a_command_sent_out_of_stamp_order_waits_for_its_own_echo():
    p = _player()
    p.sent.update({5_000_000: 1.0, 4_000_000: 1.001})                # a reset pulled the stamps back
    p._read_status(_status(4_000_000, 0.004), 1.002)
    assert list(p.sent) == [5_000_000] and p.latencies.count == 1
