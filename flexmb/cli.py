"""The ``flexmb`` command: the core's verbs plus the adapters' (ROS node, player, recording,
replay, viewing) and, in a source checkout, ``flexmb bench``.

Each adapter module owns its verbs through a ``register(verbs, run_parser)`` function; importing
it must not import rclpy or rerun (they load inside the verb's function), so ``flexmb run`` and
``flexmb replay`` work where ROS or rerun are not installed. ``benchmarks/workprecision/cli.py``
registers ``flexmb bench`` the same way; it exists only in a source checkout (a wheel ships no
``benchmarks/``), where ``flexmb bench`` then says what is missing instead of failing to parse.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from flexmb_core import cli as core_cli

# modules with a register(verbs, run_parser) function, in help order
ADAPTERS = ("ros2_node.node_cli", "flexmb_io.bag.cli", "flexmb_io.viz.cli")
# the source checkout's benchmarks (a namespace package next to this one), registering `flexmb bench`
ROOT = Path(__file__).resolve().parents[1]
BENCH_CLI = ROOT / "benchmarks" / "workprecision" / "cli.py"


def build_parser() -> argparse.ArgumentParser:
    parser = core_cli.build_parser()
    for name in ADAPTERS:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name is None or not name.startswith(exc.name):
                raise                 # the adapter exists but something it imports is missing
            continue
        mod.register(parser.verbs, parser.verb_parsers["run"])
    _register_bench(parser.verbs, parser.verb_parsers["run"])
    return parser


def _register_bench(verbs, run_parser: argparse.ArgumentParser) -> None:
    """``flexmb bench`` from ``benchmarks/workprecision/cli.py`` (its import is cheap: the benchmark
    code loads in its ``run``), or a verb that explains where it lives when this is no source checkout."""
    if BENCH_CLI.is_file():
        if str(ROOT) not in sys.path:
            sys.path.append(str(ROOT))
        from benchmarks.workprecision import cli as bench_cli

        bench_cli.register(verbs, run_parser)
        return
    # whatever follows (flags included: no prefix character is '-') reaches _bench_missing, which explains
    bn = verbs.add_parser("bench", help="work-precision reports (a source checkout's benchmarks/; not found here)",
                          prefix_chars="\0", add_help=False)
    bn.add_argument("rest", nargs="*", help=argparse.SUPPRESS)
    bn.set_defaults(func=_bench_missing)


def _bench_missing(args: argparse.Namespace) -> int:
    print(f"flexmb bench: needs a source checkout: {BENCH_CLI.relative_to(ROOT)} was not found in {ROOT} "
          "(clone the repository and install it editable, extra [bench])", file=sys.stderr)
    return 1


def main(argv: list[str] | None = None) -> int:
    return core_cli.main(argv, parser=build_parser())


if __name__ == "__main__":
    sys.exit(main())
