"""Variants of the twin node, interleaved round by round: flags, or another revision of flexmb.

Each variant is one ``flexmb demo CASE`` (node and player as two processes on DDS, realtime, 1 kHz
stamped commands; ``benchmarks/node_latency.py:run_twin``), run in turn within every round so that
a busy machine slows all alike; the report gives each round and the medians. A variant is
``LABEL=FLAGS`` (more ``flexmb demo`` flags, e.g. ``fixed=--fixed-step-margin``) or
``LABEL@TREE=FLAGS`` (the flexmb of another checkout, e.g. ``git worktree add /tmp/before REV``,
with its own numba cache); ``LABEL:CASE…`` runs that variant on another case than ``--case`` (to
compare scenes). ``this=`` is this tree as it is.

    .venv/bin/python benchmarks/node_ab.py --case frame1 --variant this= \\
        --variant fixed=--fixed-step-margin --rounds 3 --seconds 20 --name node_margin_auto
    .venv/bin/python benchmarks/node_ab.py --variant bars:bars= --variant truss:frame1t= \\
        --variant frame:frame1= --rounds 3 --name node_ab_scenes
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
from pathlib import Path

import node_latency as NL

# flattened summary keys reported, with their table headers
COLUMNS = (("deadline_misses", "missed deadlines"), ("misses_started_late", "of which began late"), ("steps", "steps"),
           ("step_margin_ms", "margin in force (ms)"),
           ("latency_p50_ms", "latency p50 (ms)"), ("latency_p99_ms", "latency p99 (ms)"),
           ("node_internal_latency_p99_ms", "in-node latency p99 (ms)"), ("commands_waited", "commands that waited"),
           ("step_wall_p99_ms", "step p99 (ms)"), ("cpu_beyond_solver_core", "CPU beyond solver (core)"))


def parse_variant(text: str, default_case: str) -> tuple[str, Path, tuple[str, ...], str]:
    """``LABEL[:CASE][@TREE]=FLAGS`` → (label, tree, flags, case)."""
    head, _, flags = text.partition("=")
    named, _, tree = head.partition("@")
    label, _, case = named.partition(":")
    if not label:
        raise SystemExit(f"--variant {text!r}: expected LABEL=FLAGS, LABEL:CASE=FLAGS or LABEL@TREE=FLAGS")
    case = case or default_case
    if case not in NL.CASES:
        raise SystemExit(f"--variant {text!r}: case {case!r} is not one of {', '.join(sorted(NL.CASES))}")
    tree_path = Path(tree).resolve() if tree else NL.ROOT
    if not (tree_path / "flexmb").is_dir():
        raise SystemExit(f"--variant {text!r}: {tree_path} is not a flexmb checkout")
    return label, tree_path, tuple(shlex.split(flags)), case


def _fmt(v) -> str:
    if v is None:
        return "–"
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def write(rows: dict[str, list[dict]], variants, args) -> None:
    cases = sorted({v[3] for v in variants})
    lines = [f"# Node variants, interleaved (`benchmarks/node_ab.py`): {', '.join(cases)}", "",
             f"{os.cpu_count()} cores; load average at the start {args.load_start[0]:.2f}, at the end "
             f"{os.getloadavg()[0]:.2f}. `flexmb demo`, realtime, Δt = 1 ms, {args.rate:g} stamped commands/s, "
             f"{args.seconds:g} s per run, {args.rounds} rounds, the variants in turn (reversed every "
             "other round)." + (f" {args.load} busy loop{'s' * (args.load > 1)} on the normal scheduler ran "
                                 "through all the rounds." if args.load else ""), ""]
    if args.note:
        lines += [args.note, ""]
    lines += ["| variant | scene | tree | flags |", "|---|---|---|---|"]
    for label, tree, flags, case in variants:
        lines.append(f"| {label} | `{NL.CASES[case][0]}` ({NL.CASES[case][1]}) | `{tree}` | "
                     f"`{' '.join(flags) or '(defaults)'}` |")
    lines += ["", "| round | variant | " + " | ".join(h for _, h in COLUMNS) + " |",
              "|---|---|" + "---|" * len(COLUMNS)]
    for k in range(args.rounds):
        for label, *_ in variants:
            if k < len(rows[label]):
                r = rows[label][k]
                lines.append(f"| {k + 1} | {label} | " + " | ".join(_fmt(r.get(c)) for c, _ in COLUMNS) + " |")
    lines += ["", "Medians:", "", "| variant | " + " | ".join(h for _, h in COLUMNS) + " |",
              "|---|" + "---|" * len(COLUMNS)]
    for label, *_ in variants:
        rs = rows[label]
        med = [statistics.median(r[c] for r in rs) if rs and rs[0].get(c) is not None else None for c, _ in COLUMNS]
        lines.append(f"| {label} | " + " | ".join(_fmt(v) for v in med) + " |")
    NL.DOCS.mkdir(parents=True, exist_ok=True)
    (NL.DOCS / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    (NL.DOCS / f"{args.name}.json").write_text(json.dumps({"rows": rows, "variants": [
        {"label": v[0], "tree": str(v[1]), "flags": list(v[2]), "case": v[3]} for v in variants]}, indent=1))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", choices=sorted(NL.CASES), default="bars", help="the variants' case unless LABEL:CASE")
    ap.add_argument("--variant", action="append", required=True,
                    help="LABEL[:CASE][@TREE]=FLAGS (repeat)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=20.0, help="s of simulated time per run")
    ap.add_argument("--rate", type=float, default=1000.0, help="the player's commands per second")
    ap.add_argument("--name", default="node_ab", help="report name: docs/benchmarks/NAME.{md,json}")
    ap.add_argument("--note", default="", help="a paragraph under the heading: what the variants are")
    ap.add_argument("--load", type=int, default=0, metavar="N",
                    help="N busy loops (processes on the normal scheduler, unpinned) run through all the rounds: "
                         "a machine that other work keeps busy")
    args = ap.parse_args()
    variants = [parse_variant(v, args.case) for v in args.variant]
    if len({v[0] for v in variants}) != len(variants):
        raise SystemExit("--variant: the labels must differ")
    args.load_start = os.getloadavg()
    rows: dict[str, list[dict]] = {v[0]: [] for v in variants}
    load = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    try:
        for k in range(args.rounds):
            for label, tree, flags, case in (variants if k % 2 == 0 else variants[::-1]):
                r = NL.run_twin(case, args.seconds, None, args.rate, extra_args=flags, tree=tree, label=label)
                rows[label].append(r)
                print(json.dumps({"round": k + 1, "variant": label} | r), flush=True)
    finally:
        for p in load:
            p.kill()
    write(rows, variants, args)
    print(f"wrote {NL.DOCS / (args.name + '.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
