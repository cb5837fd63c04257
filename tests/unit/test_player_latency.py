"""The player's command→state latency counts every command a status answers: the twin echoes the
newest command a state includes (``TwinStatus.command_stamp``), so a status echoing stamp S answers
every command stamped up to S that is still waiting — a command taken with a newer one before one
step is answered, its latency counted, not left to expire as unanswered."""

from __future__ import annotations

import types

import pytest

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


def test_tracking_compares_the_kept_poses_with_the_law_as_each_pose_alone_would():
    """Poses are kept as they come and compared with the commanded law at the end, in one call:
    the same errors as the law evaluated pose by pose (what the callback did before)."""
    import math

    import numpy as np

    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from ros2_node.player import CommandSource

    program = compile_scene(load_scene("scenes/stewart_platform_bars.yaml")).program
    p = Player.__new__(Player)
    p.source = CommandSource(["a"], lambda t: None, program.reference_poses)
    p.t0, p.until, p.poses = 0.0, 20.0, Series(width=8)
    rng = np.random.default_rng(3)
    expected_pos, expected_ang = [], []
    for t in np.sort(rng.uniform(0.0, 20.0, 50)):
        p_ref, q_ref = program.reference_pose(t)
        x = p_ref + rng.normal(0.0, 1e-3, 3)
        q = q_ref + rng.normal(0.0, 1e-4, 4)
        q /= np.linalg.norm(q)
        sec = int(t)
        msg = types.SimpleNamespace(
            header=types.SimpleNamespace(stamp=types.SimpleNamespace(sec=sec, nanosec=int(round((t - sec) * 1e9)))),
            pose=types.SimpleNamespace(position=types.SimpleNamespace(x=x[0], y=x[1], z=x[2]),
                                       orientation=types.SimpleNamespace(w=q[0], x=q[1], y=q[2], z=q[3])))
        p._on_pose(msg)
        t_msg = sec + int(round((t - sec) * 1e9)) * 1e-9
        p_ref, q_ref = program.reference_pose(t_msg)
        expected_pos.append(float(np.linalg.norm(x - p_ref)))
        expected_ang.append(2.0 * math.acos(min(1.0, abs(float(np.dot(q, q_ref))))))
    tr = p.tracking()
    assert tr["samples"] == 50
    assert tr["max_position_error_m"] == pytest.approx(max(expected_pos), rel=1e-12)
    assert tr["rms_position_error_m"] == pytest.approx(math.sqrt(np.mean(np.square(expected_pos))), rel=1e-12)
    assert tr["max_orientation_error_rad"] == pytest.approx(max(expected_ang), rel=1e-9)
