"""Verbs of the ROS adapter: ``flexmb node``, ``flexmb play``, ``flexmb demo``.

rclpy is imported inside the verbs only, so the rest of ``flexmb`` works without ROS.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

from flexmb_core.errors import FlexmbError, excerpt, writable_dir
from flexmb_io import topics as T

from .params import SPECS

# flag → parameter name (None: same name with '-' → '_')
_NODE_FLAGS = ("mode", "dt", "integrator", "publish-rate", "shape-rate", "command-source", "command-timeout",
               "command-timeout-behaviour", "duration", "idle-timeout", "qos-depth", "record", "rrd", "summary-json",
               "step-margin", "cpu-affinity", "rt-priority", "rt-threads", "cpu-dma-latency", "diagnostics-rate",
               "clock-rate", "world-frame", "frame-prefix")
# exit code of a node stopped by SIGINT/SIGTERM (after closing its recording and writing its summary)
INTERRUPTED = 130


def _discovery(args: argparse.Namespace) -> None:
    """Where DDS may go (ros2_node.dds: localhost by default, every socket on 127.0.0.1; subnet on
    request, with a warning). Before rclpy starts; the processes of ``flexmb demo`` inherit it."""
    from .dds import configure

    _, note = configure(getattr(args, "discovery_range", None))
    if note:
        print(f"flexmb {args.verb}: {note}", file=sys.stderr)


def _check_numbers(*checks: tuple[str, float, bool]) -> None:
    """``(flag, value, zero_allowed)``: each value a finite number > 0 (≥ 0 where zero is allowed),
    else :class:`FlexmbError` naming the flag — before anything starts on DDS."""
    for flag, v, zero_allowed in checks:
        if not math.isfinite(v) or v < 0 or (v == 0 and not zero_allowed):
            raise FlexmbError(f"{flag}: expected {'a finite number ≥ 0' if zero_allowed else 'a positive number'}, "
                              f"got {v}")


def _check_node_name(name: str, flag: str) -> None:
    """rclpy's own rule for a node name, as :class:`FlexmbError` naming ``flag`` (rclpy raises it
    later, from inside the node's constructor, with a traceback and a warning)."""
    from rclpy.exceptions import NameValidationException
    from rclpy.validate_node_name import validate_node_name

    try:
        validate_node_name(name)
    except NameValidationException as exc:
        raise FlexmbError(f"{flag} {excerpt(name)}: {str(exc).splitlines()[0].rstrip(':')}") from None


def cmd_node(args: argparse.Namespace) -> int:
    _discovery(args)
    from .node import run_node

    _check_node_name(args.name, "--name")

    values = {"scene": args.scene}
    for flag in _NODE_FLAGS:
        v = getattr(args, flag.replace("-", "_"))
        if v is not None:
            values[flag.replace("-", "_")] = v
    if args.mcap:
        values["record"] = args.mcap
    if args.lifecycle:
        values["autostart"] = False
    if args.fixed_step_margin:
        values["step_margin_auto"] = False
    summary = run_node(values, node_name=args.name, ros_args=args.ros_args)
    if not args.quiet:
        print(json.dumps(summary, indent=2))
    return INTERRUPTED if summary.get("interrupted") else 0


def cmd_play(args: argparse.Namespace) -> int:
    _discovery(args)
    from .player import CommandSource, run_player

    _check_numbers(("--rate", args.rate, False), ("--timeout", args.timeout, False))
    _check_node_name(args.twin, "--twin")
    if args.csv:
        if not args.names:
            print("flexmb play: --csv needs --names leg1,leg2,... (actuator order of the columns)", file=sys.stderr)
            return 1
        source = CommandSource.from_csv(args.csv, args.names.split(","))
    elif args.scene:
        source = CommandSource.from_scene(args.scene)
    else:
        print("flexmb play: give a SCENE (its commands) or --csv TABLE --names leg1,leg2,...", file=sys.stderr)
        return 1
    summary = run_player(source, json_out=args.json, twin=args.twin, mode=args.mode, until=args.until, dt=args.dt,
                         rate=args.rate, topic=args.topic, timeout=args.timeout,
                         **({} if args.lead is None else {"lead": args.lead}))
    if not args.quiet:
        print(json.dumps(summary, indent=2))
    return 0


def _fmt_ms(x) -> str:
    return "n/a" if x is None else f"{1e3 * x:.3f} ms"


def cmd_demo(args: argparse.Namespace) -> int:
    """The twin and the player as two processes on DDS; prints one summary."""
    from flexmb_core.scene import load_scene

    load_scene(args.scene)      # a bad scene is the user's error (exit 1), said once, before two processes start
    _discovery(args)
    env = dict(os.environ)
    env.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 200)))
    out = writable_dir(args.out, "--out")
    _check_numbers(("--rate", args.rate, False))
    if args.mcap and Path(args.mcap).exists() and (not Path(args.mcap).is_dir() or any(Path(args.mcap).iterdir())):
        raise FlexmbError(f"--mcap {args.mcap}: already exists (a recording is never overwritten; choose a new "
                          "path or remove it: make demo removes build/demo/bag first)")
    node_json, player_json = out / "node.json", out / "player.json"
    for f in (node_json, player_json):
        f.unlink(missing_ok=True)
    exe = [sys.executable, "-m", "flexmb.cli"]
    # the node runs until the player is done (it may start stepping before the player is up)
    node_cmd = exe + ["node", args.scene, "--mode", args.mode, "--summary-json", str(node_json), "--quiet"]
    if args.publish_rate:
        node_cmd += ["--publish-rate", str(args.publish_rate)]
    if args.mcap:
        node_cmd += ["--mcap", args.mcap]
    if args.rrd:
        node_cmd += ["--rrd", args.rrd]
    if args.rt_priority is not None:
        node_cmd += ["--rt-priority", str(args.rt_priority)]
    if args.rt_threads:
        node_cmd += ["--rt-threads", args.rt_threads]
    if args.cpu_affinity:
        node_cmd += ["--cpu-affinity", args.cpu_affinity]
    if args.cpu_dma_latency is not None:
        node_cmd += ["--cpu-dma-latency", str(args.cpu_dma_latency)]
    if args.step_margin is not None:
        node_cmd += ["--step-margin", str(args.step_margin)]
    if args.fixed_step_margin:
        node_cmd += ["--fixed-step-margin"]
    play_cmd = exe + ["play", args.scene, "--mode", args.mode, "--until", str(args.until), "--json", str(player_json),
                      "--quiet", "--timeout", "120", "--rate", str(args.rate)]
    print(f"flexmb demo: ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}, discovery on localhost only; scene {args.scene}, "
          f"{args.mode}, {args.until:g} s", flush=True)
    node = subprocess.Popen(node_cmd, env=env)
    player = subprocess.Popen(play_cmd, env=env)
    t_end = time.monotonic() + args.until * 20 + 300
    try:
        while player.poll() is None:
            if node.poll() not in (None, 0) or time.monotonic() > t_end:
                break                      # the node failed (its message is above) or we ran out of time
            time.sleep(0.1)
        if player.poll() is None:
            player.send_signal(signal.SIGINT)
            player.wait(timeout=30)
        if node.poll() is None:
            node.send_signal(signal.SIGINT)    # the node closes its recording and writes its summary
        node.wait(timeout=120)
    except (subprocess.TimeoutExpired, KeyboardInterrupt):
        print("flexmb demo: interrupted or timed out", file=sys.stderr)
        return 2
    finally:
        for proc in (player, node):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=30)
    # the node is stopped by our SIGINT once the player is done: 130 is its normal end here
    if player.returncode != 0 or node.returncode not in (0, INTERRUPTED) or not node_json.exists() \
            or not player_json.exists():
        print(f"flexmb demo: node exit {node.returncode}, player exit {player.returncode}", file=sys.stderr)
        # 1: one of them refused its input (it said why above); else the run itself failed
        return 1 if 1 in (node.returncode, player.returncode) else 2
    n = json.loads(node_json.read_text())
    p = json.loads(player_json.read_text())
    summary = {"node": n, "player": p}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    lat = p["latency_s"]
    sw = n["step_wall_time_s"]
    print(f"\n== flexmb demo: {n['scene']} ({n['mode']}, Δt = {n['dt'] * 1e3:g} ms) ==")
    print(f"  simulated {n['sim_time_s']:.3f} s in {n['wall_time_s']:.3f} s wall: RTF {n['rtf']:.3f} "
          f"(solver alone {n['solver_rtf']:.2f}); JIT warm-up {n['jit_warmup_s']:.2f} s")
    misses = n["deadline_misses"]
    if n["mode"] == "realtime":
        print(f"  {misses} missed deadlines in {n['steps']} steps" + (
            " — the twin kept real time" if misses == 0 else
            f" ({100.0 * misses / max(n['steps'], 1):.2f} %) — MISSED DEADLINES: the twin fell behind the wall "
            f"clock {misses} times ({n['overruns']} re-anchored); see the node's warnings above"))
        if misses and "deadline_misses_started_late" in n:
            print(f"  of the missed: {n['deadline_misses_started_late']} began after their deadline (the host or "
                  f"the process held the twin up), {n['deadline_misses_overran']} began in time and overran")
        if "step_margin_s" in n:
            print(f"  idle steps start {_fmt_ms(n['step_margin_s'])} before their deadline ("
                  + ("automatic: the steps' own p99.9 wall time + 0.2 ms" if n.get("step_margin_auto")
                     else "fixed step_margin") + ")")
    print(f"  steps {n['steps']}, overruns {n['overruns']}, failed steps {n['failed_steps']}, "
          f"rejected commands {sum(n['commands_rejected'].values())}, dropped publications "
          f"{n.get('dropped_publications', 0)}")
    cpu = n.get("cpu_time_s")
    if cpu:
        print(f"  node CPU {cpu['process']:.2f} s over {n['wall_time_s']:.2f} s, of which solver steps "
              f"{cpu['solver_steps']:.2f} s: the node costs {100 * cpu['beyond_solver_core_fraction']:.1f} % of a "
              "core beyond its solver")
    print(f"  step wall time p50 {_fmt_ms(sw['p50'])}, p99 {_fmt_ms(sw['p99'])}, max {_fmt_ms(sw['max'])}")
    it = n.get("newton_iterations")
    if it:
        print(f"  Newton iterations per step: mean {it['mean']:.2f}, p99 {it['p99']:.0f}, max {it['max']:.0f}")
    print(f"  command → state latency (player, over DDS, {lat['count']} commands): p50 {_fmt_ms(lat['p50'])}, "
          f"p99 {_fmt_ms(lat['p99'])}, max {_fmt_ms(lat['max'])}")
    if "tracking" in p:
        tr = p["tracking"]
        print(f"  platform tracking vs the commanded pose ({tr['samples']} poses): max {tr['max_position_error_m']:.3e} m, "
              f"rms {tr['rms_position_error_m']:.3e} m, max orientation {tr['max_orientation_error_rad']:.3e} rad")
    if args.mcap:
        print(f"  recording: {args.mcap}")
    print(f"  summary: {out / 'summary.json'}")
    return 0


def cmd_replay_live(args: argparse.Namespace) -> int:
    _discovery(args)
    from .live_replay import replay_live

    _check_numbers(("--timeout", args.timeout, False), ("--abs-tol", args.abs_tol, True),
                   ("--rel-tol", args.rel_tol, True))
    return replay_live(args.bag, out=args.out, timeout=args.timeout, abs_tol=args.abs_tol, rel_tol=args.rel_tol)


def register(verbs, run_parser) -> None:
    n = verbs.add_parser("node", help="run the twin as a ROS 2 node (rclpy, DDS on localhost)",
                         description="The flexmb twin node (a managed lifecycle node, active at start unless "
                                     "--lifecycle). Parameters can also be set with --ros-args -p name:=value "
                                     "(they win over the flags); --ros-args -r __ns:=/robot1 namespaces it.",
                         epilog="parameters (--ros-args -p NAME:=VALUE; README \"The ROS 2 twin node\" and "
                                "`ros2 param describe` explain each): " + ", ".join(s.name for s in SPECS))
    n.add_argument("scene")
    n.add_argument("--name", default=T.DEFAULT_NODE_NAME, help="node name (private topics live under it)")
    n.add_argument("--mode", choices=("realtime", "lockstep"))
    n.add_argument("--dt", type=float, help="time step (s); default: the scene's")
    n.add_argument("--integrator", choices=("newmark", "generalized_alpha", "chung_hulbert"))
    n.add_argument("--publish-rate", type=float, help="Hz (default 100; states also answer every command)")
    n.add_argument("--shape-rate", type=float, help="Hz of ~/shape (default 30; 0 disables)")
    n.add_argument("--command-source", choices=("external", "scene"))
    n.add_argument("--command-timeout", type=float, help="s (default 0.5)")
    n.add_argument("--command-timeout-behaviour", choices=("hold", "ramp_to_rest"))
    n.add_argument("--duration", type=float, help="stop after this much simulated time (s)")
    n.add_argument("--idle-timeout", type=float, help="lockstep: stop after this many s without commands")
    n.add_argument("--qos-depth", type=int)
    n.add_argument("--mcap", "--record", dest="mcap", metavar="DIR", help="record to this rosbag2/MCAP directory")
    n.add_argument("--rrd", metavar="OUT", help="log to this rerun .rrd file")
    n.add_argument("--summary-json", metavar="OUT", help="write the run summary here on exit")
    n.add_argument("--step-margin", type=float, help="realtime: s before its deadline at which an idle step "
                   "starts (default 0.0004; the least margin while step_margin_auto widens it)")
    n.add_argument("--fixed-step-margin", action="store_true", help="realtime: keep --step-margin as given "
                   "(step_margin_auto false; default: widened to the step's own p99.9 wall time + 0.2 ms)")
    n.add_argument("--cpu-affinity", help="realtime: CPU ids of the stepping thread, e.g. 1 or 0,1")
    n.add_argument("--rt-priority", type=int, help="realtime: SCHED_FIFO priority 1-99 of the stepping thread "
                   "(0: normal scheduling; default -1: 20 where the OS allows it)")
    n.add_argument("--rt-threads", choices=("stepping", "node"), help="realtime: stepping (default): the stepping "
                   "thread alone on SCHED_FIFO; node: the executor and publisher threads too, one priority below it")
    n.add_argument("--cpu-dma-latency", type=int, metavar="US", help="realtime: hold a PM QoS request on the CPUs' "
                   "idle states while running (µs of exit latency; 0: poll when idle; default -1: none)")
    n.add_argument("--diagnostics-rate", type=float, help="Hz of /diagnostics (default 1; 0 disables)")
    n.add_argument("--clock-rate", type=float, help="Hz (simulated time) of /clock (default 100)")
    n.add_argument("--world-frame", help="frame_id of headers, parent of the /tf transforms (default world)")
    n.add_argument("--frame-prefix", help="prefix of the platforms' frames (default auto: the namespace + '/')")
    n.add_argument("--lifecycle", action="store_true", help="start unconfigured: a lifecycle manager (or "
                   "lifecycle_msgs/srv/ChangeState calls) configures and activates the node")
    n.add_argument("--quiet", action="store_true", help="do not print the summary")
    n.add_argument("--ros-args", nargs=argparse.REMAINDER, default=None, help="ROS arguments (e.g. -p dt:=0.002)")
    n.set_defaults(func=cmd_node, record=None, verb="node")

    p = verbs.add_parser("play", help="stream actuator commands to a twin node (controller stand-in)")
    p.add_argument("scene", nargs="?", help="scene whose command definition to play")
    p.add_argument("--csv", help="command table: t, L1..Ln[, rates] (instead of the scene's commands)")
    p.add_argument("--names", help="actuator names of the CSV columns, comma-separated")
    p.add_argument("--twin", default=T.DEFAULT_NODE_NAME, help="node name of the twin")
    p.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    p.add_argument("--until", type=float, default=20.0, help="s of simulated time")
    p.add_argument("--dt", type=float, default=1e-3, help="lockstep: s between commands")
    p.add_argument("--rate", type=float, default=1000.0, help="realtime: commands per second")
    p.add_argument("--lead", type=float, default=None,
                   help="realtime: s ahead of the twin's time the stamped commands are for (default 0.05)")
    p.add_argument("--topic", choices=("actuator_commands", "commands"), default="actuator_commands")
    p.add_argument("--timeout", type=float, default=30.0, help="s to wait for the twin")
    p.add_argument("--json", metavar="OUT", help="write the player summary here")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_play, verb="play")

    rl = verbs.add_parser("replay-live", help="replay a recording into a live lockstep node over DDS and "
                          "compare the node's new recording with it")
    rl.add_argument("bag", help="a `flexmb run --mcap` or lockstep-node recording (one command per step)")
    rl.add_argument("--out", required=True, help="directory of the node's new recording")
    rl.add_argument("--timeout", type=float, default=30.0, help="s to wait for each acknowledgement")
    rl.add_argument("--abs-tol", type=float, default=1e-9, help="absolute tolerance of every number")
    rl.add_argument("--rel-tol", type=float, default=1e-9, help="tolerance relative to the peak of each field")
    rl.set_defaults(func=cmd_replay_live, verb="replay-live")

    d = verbs.add_parser("demo", help="twin node + player as two processes on DDS, with a summary")
    d.add_argument("scene", nargs="?", default="scenes/stewart_platform_1el_truss.yaml",
                   help="scene file (default: the flexible-leg twin of `make demo`)")
    d.add_argument("--mode", choices=("realtime", "lockstep"), default="realtime")
    d.add_argument("--until", type=float, default=20.0)
    d.add_argument("--publish-rate", type=float)
    d.add_argument("--rate", type=float, default=1000.0, help="realtime: the player's commands per second")
    d.add_argument("--mcap", metavar="DIR", help="record the node's run here")
    d.add_argument("--rrd", metavar="OUT")
    d.add_argument("--rt-priority", type=int, help="SCHED_FIFO priority of the node's stepping thread")
    d.add_argument("--rt-threads", choices=("stepping", "node"), help="the node's rt_threads: stepping (default: "
                   "only the stepping thread on SCHED_FIFO) or node (the executor and publisher threads too)")
    d.add_argument("--cpu-affinity", help="CPU ids of the node's stepping thread, e.g. 1")
    d.add_argument("--cpu-dma-latency", type=int, metavar="US", help="the node's cpu_dma_latency: a PM QoS request "
                   "on the CPUs' idle states (µs; 0: poll when idle; default -1: none)")
    d.add_argument("--step-margin", type=float, help="s before its deadline at which the node's idle step "
                   "starts (the node's step_margin; more than Δt keeps the twin ahead of the wall clock)")
    d.add_argument("--fixed-step-margin", action="store_true", help="keep the node's step_margin as given "
                   "(step_margin_auto false)")
    d.add_argument("--out", default="build/demo", help="directory of the JSON summaries")
    d.set_defaults(func=cmd_demo, verb="demo")
    for parser in (n, p, rl, d):
        parser.add_argument("--discovery-range", choices=("localhost", "subnet"), default=None,
                            help="where DDS may reach: localhost (default: every socket on 127.0.0.1) or subnet "
                                 "(other machines, no DDS security; a warning); default from FLEXMB_DISCOVERY_RANGE, "
                                 "else ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET, else localhost")
