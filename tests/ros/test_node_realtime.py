"""The realtime twin on real DDS: a twin that cannot keep up says so (log, status, /diagnostics),
and the node's summary accounts for its deadlines and CPU."""

from __future__ import annotations

import json
import os

import pytest

pytest.importorskip("diagnostic_msgs")
from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402

from dds_harness import NodeProcess, TwinClient
from flexmb_io import topics as T

pytestmark = pytest.mark.ros
SCENE = "scenes/stewart_platform_bars.yaml"
OK, WARN = DiagnosticStatus.OK, DiagnosticStatus.WARN          # byte fields: b'\x00', b'\x01'



@pytest.mark.timeout(180)
def test_an_overloaded_twin_reports_that_it_is_behind(tmp_path, dds_env):
    """Δt = 20 µs: the bar twin's step (~20 µs of solver alone, more with the Python around it)
    cannot keep 50 kHz, so every window of steps misses deadlines. The node must log it, put the reason in status.message and
    raise the deadlines entry of /diagnostics to WARN."""
    summary = tmp_path / "s.json"
    node = NodeProcess([SCENE, "--mode", "realtime", "--dt", "2e-5", "--duration", "1.2", "--publish-rate", "2000",
                        "--diagnostics-rate", "5", "--summary-json", str(summary), "--quiet"], dds_env,
                       tmp_path / "node.log")
    client = TwinClient()
    try:
        client.wait_for_twin(node)
        client.spin_until(lambda: any("behind real time" in s.message for s in client.statuses()), 60,
                          "a status that says the twin is behind", node)
        client.spin_until(lambda: any(st.name.endswith(": deadlines") and st.level == WARN
                                      for d in client.received[T.DIAGNOSTICS.name] for st in d.status), 30,
                          "a WARN deadlines entry on /diagnostics", node)
    finally:
        client.close()
    node.proc.wait(timeout=120)
    assert node.stop() == 0, node.log()          # it ran its duration out
    log = node.log_path.read_text()
    assert "behind real time:" in log and "missed their deadline" in log, log[-2000:]
    s = json.loads(summary.read_text())
    assert s["deadline_misses"] > 0 and s["steps"] == 60000
    diag = [st for d in client.received[T.DIAGNOSTICS.name] for st in d.status]
    names = {st.name for st in diag}
    assert {"flexmb_twin: solver", "flexmb_twin: deadlines", "flexmb_twin: commands"} <= names
    warn = next(st for st in diag if st.name.endswith(": deadlines") and st.level == WARN)
    values = {kv.key: kv.value for kv in warn.values}
    assert int(values["recent_misses"]) > 0 and "behind real time" in warn.message


@pytest.mark.timeout(120)
@pytest.mark.parametrize("rt_threads", ["node", "stepping"])
def test_a_twin_that_keeps_up_reports_its_timing(tmp_path, dds_env, rt_threads):
    """At the scene's Δt the bar twin keeps real time; the summary carries the deadline slack, the
    step wall times and the node's CPU beyond its solver, and /diagnostics says OK for the solver.
    Its threads' scheduling as each found it in force: with ``rt_threads: node`` the executor and the
    publisher one SCHED_FIFO priority below the stepping thread, with ``stepping`` on the normal
    scheduler (all of them there where the OS allows no SCHED_FIFO). With ``rt_threads: node`` it also
    holds a PM QoS request (``cpu_dma_latency`` 0) where the OS takes one, and says so."""
    summary = tmp_path / "s.json"
    qos = ["--cpu-dma-latency", "0"] if rt_threads == "node" else []
    node = NodeProcess([SCENE, "--mode", "realtime", "--duration", "6", "--diagnostics-rate", "5",
                        "--rt-threads", rt_threads, "--summary-json", str(summary), "--quiet", *qos], dds_env,
                       tmp_path / "node.log")
    client = TwinClient()
    try:
        client.wait_for_twin(node)
        client.spin_until(lambda: len(client.received[T.DIAGNOSTICS.name]) >= 2, 30, "/diagnostics", node)
    finally:
        client.close()
    node.proc.wait(timeout=60)
    log = node.log()
    assert node.stop() == 0, log
    s = json.loads(summary.read_text())
    assert s["steps"] == 6000 and s["failed_steps"] == 0
    assert s["step_wall_time_s"]["count"] == 6000 and s["deadline_slack_s"]["count"] == 6000
    cpu = s["cpu_time_s"]
    assert cpu["process"] > cpu["solver_steps"] > 0
    solver = [st for d in client.received[T.DIAGNOSTICS.name] for st in d.status if st.name.endswith(": solver")]
    assert solver and all(st.level == OK for st in solver)
    fifo = s["fifo_priority"]
    helpers = fifo["stepping"] - 1 if fifo["stepping"] and rt_threads == "node" else 0
    assert fifo["executor"] == fifo["publisher"] == helpers, fifo
    if not qos:
        assert s["cpu_dma_latency_us"] is None
    elif os.access("/dev/cpu_dma_latency", os.W_OK):
        assert s["cpu_dma_latency_us"] == 0 and "PM QoS: CPU idle-state exit latency ≤ 0 µs" in log
    else:
        assert s["cpu_dma_latency_us"] is None and "cpu_dma_latency 0 µs not applied" in log


@pytest.mark.timeout(180)
def test_a_log_nobody_reads_stalls_nothing(tmp_path, dds_env):
    """stderr is a pipe nobody reads (``flexmb node … 2>&1 | less``, paused): a flood of rejected
    commands, each warned about (``log_throttle`` 0), fills it many times over. The twin must go on
    stepping and answering, stop on SIGINT with 130, and count the log lines it could not write
    (before, the publisher thread blocked in its log write and the node grew without bound)."""
    import subprocess

    from std_msgs.msg import Float64MultiArray

    summary = tmp_path / "s.json"
    node = NodeProcess([SCENE, "--mode", "realtime", "--summary-json", str(summary), "--quiet",
                        "--ros-args", "-p", "log_throttle:=0.0"], dds_env, tmp_path / "node.log",
                       stderr=subprocess.PIPE)
    client = TwinClient()
    try:
        client.wait_for_twin(node)
        for _ in range(3000):          # ≈ 150 bytes of warning each: 450 kB against a 64 kB pipe
            client.publish(T.COMMANDS, Float64MultiArray(data=[1.0, 2.0]))
            client.executor.spin_once(timeout_sec=5e-4)
        client.spin_until(lambda: client.statuses()[-1].rejected_commands >= 1000, 60,
                          "the twin to have rejected 1000 of the flood", node)
        t_flood = client.statuses()[-1].sim_time
        before = len(client.statuses())
        client.spin_until(lambda: len(client.statuses()) > before + 20, 20,
                          "statuses after the log's pipe filled", node)
        assert client.statuses()[-1].sim_time > t_flood + 0.01
    finally:
        client.close()
        rc = node.stop(timeout=20.0)        # SIGINT, then SIGKILL after 20 s: never left running
    assert rc == 130, node.log()
    s = json.loads(summary.read_text())
    assert s["commands_rejected"]["size"] >= 1000, s["commands_rejected"]
    assert s["log_lines_dropped"] > 0, s
