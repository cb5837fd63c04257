"""Executables of the ROS 2 package ``flexmb`` (``ros/flexmb/setup.py``): ``ros2 run flexmb flexmb_node``.

``flexmb_node [SCENE] [flexmb node flags] [--ros-args ...]`` is ``flexmb node`` whose scene may also
come from the ``scene`` parameter, as a launch file passes it
(``--ros-args -p scene:=/path/scene.yaml`` or ``--params-file``). A ``-p`` parameter wins over the
positional SCENE and the flags; without either, the node stops with
``parameter 'scene': required``.

``flexmb_player SCENE [flexmb play flags]`` is ``flexmb play``; ROS arguments that a launch file
appends (``--ros-args ...``) are dropped, since the player names the twin with ``--twin``.
"""

from __future__ import annotations

import sys

ROS_ARGS = "--ros-args"


def split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """``argv`` split at the first ``--ros-args``: (own arguments, ROS arguments from it on)."""
    if ROS_ARGS not in argv:
        return list(argv), []
    i = argv.index(ROS_ARGS)
    return list(argv[:i]), list(argv[i:])


def node_argv(argv: list[str]) -> list[str]:
    """The ``flexmb`` command line that runs ``flexmb_node argv``."""
    own, ros = split_ros_args(argv)
    if not own or own[0].startswith("-"):
        own = [""] + own          # no positional scene: the 'scene' parameter must name it
    return ["node", *own, *ros]


def player_argv(argv: list[str]) -> list[str]:
    """The ``flexmb`` command line that runs ``flexmb_player argv``."""
    own, _ = split_ros_args(argv)
    return ["play", *own]


def node_main(argv: list[str] | None = None) -> int:
    from .cli import main

    return main(node_argv(sys.argv[1:] if argv is None else argv))


def player_main(argv: list[str] | None = None) -> int:
    from .cli import main

    return main(player_argv(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(node_main())
