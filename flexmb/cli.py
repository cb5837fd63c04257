"""The ``flexmb`` command: the core's verbs plus the adapters' (ROS node, player, recording,
replay, viewing).

Each adapter module owns its verbs through a ``register(verbs, run_parser)`` function; importing
it must not import rclpy or rerun (they load inside the verb's function), so ``flexmb run`` and
``flexmb replay`` work where ROS or rerun are not installed.
"""

from __future__ import annotations

import importlib
import sys

from flexmb_core import cli as core_cli

# modules with a register(verbs, run_parser) function, in help order
ADAPTERS = ("ros2_node.node_cli", "ros2_node.bag.cli", "ros2_node.viz.cli")


def build_parser():
    parser = core_cli.build_parser()
    for name in ADAPTERS:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name is None or not name.startswith(exc.name):
                raise                 # the adapter exists but something it imports is missing
            continue
        mod.register(parser.verbs, parser.verb_parsers["run"])
    return parser


def main(argv: list[str] | None = None) -> int:
    return core_cli.main(argv, parser=build_parser())


if __name__ == "__main__":
    sys.exit(main())
