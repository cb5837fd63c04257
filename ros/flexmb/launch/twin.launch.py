"""The flexmb twin and, optionally, the command player: ``ros2 launch flexmb twin.launch.py``.

Launch arguments (``name:=value``):

- ``scene``: scene YAML of the mechanism (default: the package's
  ``share/flexmb/scenes/stewart_platform_bars.yaml``);
- ``namespace``: the twin's namespace (default: none), e.g. ``robot1``;
- ``mode``: ``realtime`` (default) or ``lockstep``, for the twin and the player alike;
- ``play``: ``true`` (default) streams the scene's own command program to the twin with
  ``flexmb_player``; ``false`` starts the twin alone (commands come from your controllers);
- ``until``: seconds of simulated time the player plays (default 20);
- ``stop_after_play``: ``true`` shuts the launch down when the player is done (default ``false``);
- ``record``: rosbag2/MCAP directory the twin records to (default: none).

The twin runs as node ``flexmb_twin`` (``flexmb_node``); its other parameters keep their defaults
and can be changed at run time (``ros2 param set``) or in a copy of this file. DDS discovery stays
on this machine unless ``ROS_AUTOMATIC_DISCOVERY_RANGE`` says otherwise (see the README).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = "flexmb"
TWIN_NAME = "flexmb_twin"
DEFAULT_SCENE = "stewart_platform_bars.yaml"

ARGUMENTS = (
    ("scene", "", f"scene YAML file (empty: share/{PACKAGE}/scenes/{DEFAULT_SCENE})"),
    ("namespace", "", "namespace of the twin (empty: none)"),
    ("mode", "realtime", "realtime or lockstep (twin and player)"),
    ("play", "true", "stream the scene's command program to the twin with flexmb_player"),
    ("until", "20.0", "s of simulated time the player plays"),
    ("stop_after_play", "false", "shut the launch down when the player is done"),
    ("record", "", "rosbag2/MCAP directory the twin records to (empty: no recording)"),
)


def _flag(text: str, name: str) -> bool:
    value = text.strip().lower()
    if value not in ("true", "false", "1", "0", "yes", "no"):
        raise ValueError(f"launch argument '{name}': expected true or false, got {text[:40]!r}")
    return value in ("true", "1", "yes")


def twin_and_player(context, *args, **kwargs):
    """The actions, once the launch arguments are known (an OpaqueFunction's body)."""
    arg = {name: LaunchConfiguration(name).perform(context) for name, _, _ in ARGUMENTS}
    scene = arg["scene"] or os.path.join(get_package_share_directory(PACKAGE), "scenes", DEFAULT_SCENE)
    namespace = arg["namespace"].strip("/")
    parameters = {"scene": scene, "mode": arg["mode"]}
    if arg["record"]:
        parameters["record"] = arg["record"]
    where = {"namespace": namespace} if namespace else {}       # none given: the launch's own namespace
    twin = Node(package=PACKAGE, executable="flexmb_node", name=TWIN_NAME, parameters=[parameters],
                output="screen", emulate_tty=True, **where)
    actions = [twin]
    if _flag(arg["play"], "play"):
        # the player names the twin by its fully qualified name; its private topics live under it
        twin_path = f"{namespace}/{TWIN_NAME}" if namespace else TWIN_NAME
        player = Node(package=PACKAGE, executable="flexmb_player", name="flexmb_player", output="screen",
                      arguments=[scene, "--mode", arg["mode"], "--until", arg["until"], "--twin", twin_path,
                                 "--timeout", "120"])
        actions.append(player)
        if _flag(arg["stop_after_play"], "stop_after_play"):
            actions.append(RegisterEventHandler(OnProcessExit(
                target_action=player, on_exit=[EmitEvent(event=Shutdown(reason="flexmb_player is done"))])))
    return actions


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text) for name, default, text in ARGUMENTS]
        + [OpaqueFunction(function=twin_and_player)])
