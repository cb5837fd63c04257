"""The recording adapter's command line: ``flexmb run --mcap``, ``flexmb replay``, ``flexmb bag``.

Importing this module loads neither rclpy nor the MCAP libraries (they load inside the verbs).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from flexmb_core.cli import add_run_hook
from flexmb_core.errors import writable_file

from .calibrate_cli import register as register_calibrate
from .defaults import DEFAULT_RECORD_RATE, MAX_SHAPE_RATE
from .tolerances import DEFAULT_TOLERANCES, UNITS

REPLAY_HELP = """Re-run a recording's commands through the twin (lockstep, no ROS) and compare every
recorded output with the replay, field by field.

The scene and solver settings come from the bag (attachment scene.yaml, metadata 'flexmb');
--scene and --override replay against something else (e.g. to check that a change is seen).

Tolerances (--tolerance KEY=VALUE, repeatable; 'force' and 'energy' are fractions of the field's
peak |value| over the bag):
""" + "\n".join(f"  {k:10s} {v:g} {UNITS[k]}" for k, v in DEFAULT_TOLERANCES.items()) + """

Exit codes: 0 every field within tolerance; 3 a deviation beyond tolerance, a structural mismatch,
a failed replay step or recorded outputs never reached; 1 bad input.

flexmb replay DIR (a directory of bags, e.g. bags/): every bag under DIR, each a task on Dask
distributed (--scheduler ADDRESS, or a local cluster of --workers processes, default one per core;
one bag or --workers 1: in this process), the same --scene/--override/--tolerance for each; a bag
listed in DIR/manifest.yaml starts from its entry's tolerances. One table (bag, ok, worst field,
exit code); --json OUT has one entry per bag. Exit 0 every bag within tolerance, 3 any regression
(or a listed bag missing), 1 bad input (no bag under DIR, a bad manifest or flag, or only bags
that cannot be replayed).
"""

BAG_HELP = """Inspect and repair recordings.

  flexmb bag info BAG            topics, counts, time span, scene, settings; says if the file is cut short
  flexmb bag recover IN OUT      write a complete bag from everything readable in IN (e.g. after SIGKILL:
                                 up to the last complete chunk)
  flexmb bag regenerate          re-record every reference bag listed in bags/manifest.yaml
"""


def _flatten(items) -> list[str]:
    return [x for group in (items or []) for x in group]


def cmd_replay(args: argparse.Namespace) -> int:
    from .replay import replay
    from .replay_many import is_bag_dir

    if args.json:
        writable_file(args.json, "--json", inputs=(args.bag, args.scene))   # before the replay
    if Path(args.bag).is_dir() and not is_bag_dir(Path(args.bag)):
        return _replay_dir(args)

    report = replay(args.bag, tolerances=_flatten(args.tolerance), scene_path=args.scene,
                    overrides=_flatten(args.override))
    return _emit(report, args)


def _emit(report, args: argparse.Namespace) -> int:
    """Write ``--json``, print the report (unless ``--quiet`` and all is well); the exit code."""
    if args.json:
        Path(args.json).write_text(json.dumps(report.as_dict(), indent=2) + "\n")
    if not args.quiet or not report.ok:
        print(report.format())
    return report.exit_code


def _replay_dir(args: argparse.Namespace) -> int:
    from .replay_many import replay_dir

    def finished(result) -> None:       # a failing bag's full report, as `flexmb replay BAG` prints it
        if not result.ok and result.report is not None:
            print(result.report.format(), flush=True)

    report = replay_dir(args.bag, tolerances=_flatten(args.tolerance), scene_path=args.scene,
                        overrides=_flatten(args.override), scheduler=args.scheduler, workers=args.workers,
                        on_result=finished)
    return _emit(report, args)


def cmd_bag_info(args: argparse.Namespace) -> int:
    from .info import bag_info, format_info

    info = bag_info(args.bag)
    print(json.dumps(info, indent=2) if args.json else format_info(info))
    return 0


def cmd_bag_recover(args: argparse.Namespace) -> int:
    from .reader import BagReader, recover

    r = recover(args.input, args.output)
    out = BagReader(args.output)
    first, last = out.time_range_ns()
    state = f"cut short ({r.problem}); kept every complete chunk" if r.truncated else "complete already"
    print(f"{args.input}: {state}\nwrote {args.output}: {len(out.messages_raw)} messages on {len(out.topics())} "
          f"topics, t = {first * 1e-9:.6g} … {last * 1e-9:.6g} s")
    return 0


def cmd_bag_regenerate(args: argparse.Namespace) -> int:
    from .regenerate import regenerate

    return regenerate(Path(args.dir), only=args.only)


def _make_hook(args, scene, model):
    if not getattr(args, "mcap", None):
        return None
    from .run_hook import make_hook

    return make_hook(args, scene, model)


def register(verbs, run_parser: argparse.ArgumentParser) -> None:
    """Add ``replay`` and ``bag`` to the verbs and ``--mcap OUT`` / ``--record-rate HZ`` to ``run``."""
    r = verbs.add_parser("replay", help="replay a recording's commands and compare its outputs (regression)",
                         description=REPLAY_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("bag", metavar="BAG", help="rosbag2 directory (or .mcap) from flexmb run/node --mcap, or a "
                                              "directory of bags (DIR: every bag under it)")
    r.add_argument("--json", metavar="OUT", help="write the report (every field's worst deviation) as JSON")
    r.add_argument("--tolerance", metavar="KEY=VALUE", nargs="+", action="append",
                   help="override a tolerance (keys above)")
    r.add_argument("--scene", metavar="PATH", help="replay against this scene file instead of the recorded one")
    r.add_argument("--override", metavar="KEY=VALUE", nargs="+", action="append",
                   help="edit the scene before replaying, e.g. materials.steel.E=2.2e11 or solver.tolerance=1e-6")
    r.add_argument("--quiet", action="store_true", help="print the report only when the replay fails")
    r.add_argument("--scheduler", metavar="ADDRESS",
                   help="DIR: replay the bags as tasks of this Dask scheduler (tcp://host:8786)")
    r.add_argument("--workers", type=int, metavar="N",
                   help="DIR: worker processes of the local Dask cluster (default: one per core, at most one per "
                        "bag; 1: one bag after another in this process)")
    r.set_defaults(func=cmd_replay)

    b = verbs.add_parser("bag", help="inspect, recover or regenerate recordings", description=BAG_HELP,
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    bs = b.add_subparsers(dest="bag_verb", required=True)
    i = bs.add_parser("info", help="what a bag holds (tolerates a file cut short)")
    i.add_argument("bag", metavar="BAG")
    i.add_argument("--json", action="store_true", help="print as JSON")
    i.set_defaults(func=cmd_bag_info)
    rc = bs.add_parser("recover", help="write a complete bag from a damaged or cut-short one")
    rc.add_argument("input", metavar="IN", help="bag directory or .mcap")
    rc.add_argument("output", metavar="OUT", help="new bag directory")
    rc.set_defaults(func=cmd_bag_recover)
    g = bs.add_parser("regenerate", help="re-record the reference bags of a manifest")
    g.add_argument("--dir", default="bags", help="directory with manifest.yaml (default: bags)")
    g.add_argument("--only", metavar="NAME", nargs="+", help="only these entries")
    g.set_defaults(func=cmd_bag_regenerate)

    run_parser.add_argument("--mcap", metavar="OUT",
                            help="record the run to this rosbag2/MCAP directory (replay with flexmb replay)")
    run_parser.add_argument("--record-rate", type=float, default=DEFAULT_RECORD_RATE, metavar="HZ",
                            help=f"outputs recorded per simulated second (default {DEFAULT_RECORD_RATE:g}; shape at "
                                 f"most {MAX_SHAPE_RATE:g} Hz; commands every step; always the last state)")
    add_run_hook(run_parser, _make_hook)
    register_calibrate(verbs)

