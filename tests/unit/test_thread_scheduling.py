"""The node's threads on SCHED_FIFO: the helpers' priority below the stepping thread's, raised and
put back on the calling thread only (a thread of its own here, so that the test process keeps its
scheduling whatever happens)."""

from __future__ import annotations

import os
import threading

import pytest

from flexmb_io.realtime import (HELPER_PRIORITY_BELOW, fifo_priority_in_force, helper_priority, raise_to_fifo,
                                restore_scheduling)

pytestmark = pytest.mark.skipif(not hasattr(os, "sched_setscheduler"), reason="no POSIX thread scheduling")


def test_the_helpers_run_just_below_the_stepping_thread_and_never_below_one():
    assert helper_priority(20) == 20 - HELPER_PRIORITY_BELOW == 19
    assert helper_priority(1) == 1
    assert helper_priority(0) == 0         # a stepping thread on the normal scheduler: helpers stay there too


def _in_a_thread(fn):
    out = {}

    def run():
        try:
            out["value"] = fn()
        except BaseException as exc:      # reported to the test, not lost with the thread
            out["error"] = exc

    t = threading.Thread(target=run)
    t.start()
    t.join(10.0)
    if "error" in out:
        raise out["error"]
    return out["value"]


def test_a_raised_thread_runs_on_fifo_and_goes_back_to_its_scheduling():
    def raise_and_restore():
        start = (os.sched_getscheduler(0), fifo_priority_in_force())
        before = raise_to_fifo(7)
        raised = fifo_priority_in_force()
        restore_scheduling(before)
        return start, before, raised, (os.sched_getscheduler(0), fifo_priority_in_force())

    mine = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    start, before, raised, after = _in_a_thread(raise_and_restore)
    if before is None:                    # the OS refused (no CAP_SYS_NICE, no rtprio limit): nothing changed
        assert raised == 0 and after == start
    else:
        assert raised == 7
        assert after == start and before[0] == start[0]
    # scheduling is per thread: the test's own was never touched
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == mine
