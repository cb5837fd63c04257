"""``flexmb view`` and ``flexmb run --rrd``: the rerun adapter's command line.

Importing this module imports neither rerun nor rclpy: they load inside the verb.
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
from pathlib import Path

from flexmb_core.cli import add_run_hook
from flexmb_core.errors import FlexmbError, writable_file

from .hook import DEFAULT_PERIOD

VIEW_HELP = """Show a recording in rerun: deformed members and platforms in 3D, actuator lengths and
forces, solver health and energies as plots, on the timeline sim_time (message stamps).

BAG_OR_RUN is a rosbag2 directory (metadata.yaml + *.mcap), a bare .mcap written with the twin's
topics (flexmb node / flexmb run --mcap), or an .rrd (then only --spawn / --png apply).
Without --rrd, --spawn or --png the recording is written to ./<name>.rrd.

Headless PNG (no display, no GPU): apt-get install mesa-vulkan-drivers, then
  flexmb view BAG --rrd out.rrd --png out.png
"""


def _require_rerun(what: str) -> None:
    try:
        import rerun  # noqa: F401
    except ImportError:
        raise FlexmbError(f"{what} needs rerun-sdk: pip install 'rerun-sdk==0.41.*' "
                          "(the 'viz' extra of flexmb)") from None


def cmd_view(args: argparse.Namespace) -> int:
    from .snapshot import SnapshotUnavailable, open_viewer, screenshot

    _require_rerun("flexmb view")
    if not (math.isfinite(args.period) and args.period >= 0):
        raise FlexmbError(f"--period must be ≥ 0 s, got {args.period}")
    size = args.window_size.split("x")
    if len(size) != 2 or not all(x.isdigit() and 0 < int(x) <= 16384 for x in size):
        raise FlexmbError(f"--window-size: expected WIDTHxHEIGHT in points (1 to 16384 each), e.g. 1600x900, "
                          f"got {args.window_size[:40]!r}")
    if not (args.exaggerate > 0 and math.isfinite(args.exaggerate)):
        raise FlexmbError(f"--exaggerate must be a finite factor > 0, got {args.exaggerate}")
    if args.exaggerate != 1.0 and Path(args.recording).suffix == ".rrd":
        raise FlexmbError("--exaggerate applies to a bag or .mcap (an .rrd is shown as it was logged)")
    src = Path(args.recording)
    if args.png:
        writable_file(args.png, "--png", inputs=(src,))     # before the rendering: no work lost to a bad path
    layout = None
    temporary = False
    empty = False
    if src.suffix == ".rrd":
        if not src.is_file():
            raise FlexmbError(f"{src}: no such .rrd file")
        if src.stat().st_size == 0:
            raise FlexmbError(f"{src}: an empty file; expected a rerun recording (.rrd)")
        rrd = src
    else:
        from .view import view_recording

        if args.rrd:
            rrd = Path(args.rrd)
        elif args.spawn or args.png:
            rrd, temporary = _temp_rrd(src), True
        else:
            rrd = Path(src.resolve().stem + ".rrd")
        report = view_recording(src, rrd_path=str(rrd), period=args.period, exaggerate=args.exaggerate)
        layout = report.layout
        n = sum(report.messages.values())
        empty = n == 0
        span = f"t = {report.t_first:.6g} … {report.t_last:.6g} s" if n else "no messages"
        print(f"{src}: logged {n} messages on {len(report.messages)} topics ({span})"
              + (f", scene '{report.scene}'" if report.scene else ", no scene attached (geometry from markers)")
              + (" — the file ends early (read up to its last complete record)" if report.truncated else "")
              + (f"; members' bending drawn ×{args.exaggerate:g}" if args.exaggerate != 1.0 else ""))
        if args.rrd or not (args.spawn or args.png):
            print(f"wrote {rrd}")
    opened = False
    try:
        if args.png and empty:
            # the viewer would wait for data that never comes (up to the screenshot's timeout)
            print(f"flexmb view: --png skipped: {src} holds no messages to draw", file=sys.stderr)
        elif args.png:
            try:
                print(f"wrote {screenshot(rrd, args.png, layout, size=args.window_size)}")
            except SnapshotUnavailable as exc:
                print(f"flexmb view: --png skipped: {exc}", file=sys.stderr)
        if args.spawn:
            try:
                open_viewer(rrd)
                opened = True
                print(f"opened the rerun viewer on {rrd} (bound to 127.0.0.1)")
            except SnapshotUnavailable as exc:
                print(f"flexmb view: --spawn skipped: {exc}", file=sys.stderr)
    finally:
        if temporary and not opened:
            shutil.rmtree(rrd.parent, ignore_errors=True)      # nobody else will read it
    return 0


def _temp_rrd(src: Path) -> Path:
    import tempfile

    # --spawn / --png alone: the viewer needs a file, which outlives this process for --spawn
    return Path(tempfile.mkdtemp(prefix="flexmb-view-")) / (src.resolve().stem + ".rrd")


def _make_hook(args, scene, model):
    if not getattr(args, "rrd", None):
        return None
    _require_rerun("flexmb run --rrd")
    writable_file(args.rrd, "--rrd", inputs=(args.scene,))
    from .hook import make_hook

    return make_hook(args, scene, model)


def register(verbs, run_parser: argparse.ArgumentParser) -> None:
    """Add ``view`` to the verbs and ``--rrd OUT`` / ``--rrd-period S`` to ``run``."""
    v = verbs.add_parser("view", help="show a recording in rerun (3D shapes, plots; headless PNG)",
                         description=VIEW_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    v.add_argument("recording", metavar="BAG_OR_RUN", help="rosbag2 directory, .mcap or .rrd")
    v.add_argument("--rrd", metavar="OUT", help="write the rerun recording (.rrd) here")
    v.add_argument("--spawn", action="store_true", help="open the native rerun viewer (needs a display)")
    v.add_argument("--png", metavar="OUT.png", help="render a PNG headless (Vulkan; lavapipe without a GPU)")
    v.add_argument("--period", type=float, default=0.0, metavar="S",
                   help="keep at most one message per topic every S seconds of stamp time (default: all)")
    v.add_argument("--window-size", default="1600x900", metavar="WxH", help="PNG size in points (default 1600x900)")
    v.add_argument("--exaggerate", type=float, default=1.0, metavar="K",
                   help="draw each member's bending (its deviation from its chord) K times as large; ends, "
                        "rigid motion and stretch as computed (default 1)")
    v.set_defaults(func=cmd_view)
    run_parser.add_argument("--rrd", metavar="OUT", help="log the run into a rerun recording (.rrd)")
    run_parser.add_argument("--rrd-period", type=float, default=DEFAULT_PERIOD, metavar="S",
                            help=f"simulated time between logged states (default {DEFAULT_PERIOD} s, 0: every "
                                 "step; the first and last states are always logged)")
    add_run_hook(run_parser, _make_hook)
