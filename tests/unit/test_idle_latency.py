"""The node's PM QoS request (``cpu_dma_latency``): written as the kernel reads it, held while the
twin runs, dropped on release; a refusal says why. On a Linux machine whose CPUs have an idle state
slower to leave than the request, the kernel keeps them out of it while the request is held."""

from __future__ import annotations

import glob
import os
import sys
import time

import pytest

from flexmb_io.realtime import CPU_DMA_LATENCY, IdleLatencyRequest


def test_the_request_is_one_native_int32_written_and_held_until_release(tmp_path):
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    req = IdleLatencyRequest(25, path=str(dev))
    assert req.acquire() == "" and req.held
    assert dev.read_bytes() == (25).to_bytes(4, sys.byteorder, signed=True)
    req.release()
    assert not req.held
    req.release()                      # twice is harmless


def test_a_refused_request_says_which_device_and_why(tmp_path):
    req = IdleLatencyRequest(0, path=str(tmp_path / "missing"))
    why = req.acquire()
    assert not req.held and why.startswith(str(tmp_path / "missing")) and "No such file" in why


def _deep_states():
    """(usage file, exit latency µs) of every CPU idle state slower to leave than 0 µs."""
    out = []
    for state in glob.glob("/sys/devices/system/cpu/cpu[0-9]*/cpuidle/state[0-9]*"):
        try:
            latency = int(open(os.path.join(state, "latency")).read())
            disabled = open(os.path.join(state, "disable")).read().strip() == "1"
        except OSError:
            continue
        if latency > 0 and not disabled:
            out.append((os.path.join(state, "usage"), latency))
    return out


def _usage(states) -> int:
    return sum(int(open(path).read()) for path, _ in states)


def _grows(states, within: float = 2.0) -> bool:
    """Whether some CPU enters one of ``states`` within ``within`` s (a busy machine may not)."""
    start, end = _usage(states), time.monotonic() + within
    while time.monotonic() < end:
        time.sleep(0.05)
        if _usage(states) > start:
            return True
    return False


@pytest.mark.skipif(not os.access(CPU_DMA_LATENCY, os.W_OK) or not _deep_states(),
                    reason="no writable PM QoS device or no idle state slower to leave than 0 µs")
def test_while_held_the_cpus_stay_out_of_the_idle_states_it_excludes():
    states = _deep_states()
    if not _grows(states):
        pytest.skip("the CPUs stayed busy for 2 s: no idle-state entries to compare with")
    req = IdleLatencyRequest(0)
    assert req.acquire() == ""
    try:
        time.sleep(0.05)                # a CPU idle when the request came leaves its state first
        held = _usage(states)
        time.sleep(0.3)
        assert _usage(states) == held
    finally:
        req.release()
    assert _grows(states)               # released: the idle states are used again
