"""``ros/flexmb/launch/twin.launch.py`` without ROS 2's launch (not on PyPI), and the ROS package's metadata.

The launch file is imported against stand-ins (``launch_stub``) that accept only the real classes'
keyword arguments; its actions are checked against the package: the executables are the
``console_scripts`` of ``ros/flexmb/setup.py``, every twin parameter is a declared node parameter,
the player's arguments parse with ``flexmb play``. The colcon test (``test_colcon_package``) then
runs the twin exactly as the launch file starts it.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import py_compile
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from launch_stub import evaluate, load_launch_file

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "ros" / "flexmb"
LAUNCH = PKG / "launch" / "twin.launch.py"
SCENE = str(ROOT / "scenes" / "stewart_platform_bars.yaml")


def _console_scripts() -> dict[str, str]:
    """name → 'module:function' of ros/flexmb/setup.py's console_scripts (read, not run)."""
    tree = ast.parse((PKG / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == "console_scripts":
                    entries = [ast.literal_eval(e) for e in value.elts]
                    return dict(tuple(p.strip() for p in e.split("=", 1)) for e in entries)
    raise AssertionError("ros/flexmb/setup.py: no console_scripts")


def _nodes(actions) -> dict[str, object]:
    return {a.kwargs["executable"]: a for a in actions if a.kind == "Node"}


def test_launch_file_compiles(tmp_path):
    py_compile.compile(str(LAUNCH), cfile=str(tmp_path / "twin.launch.pyc"), doraise=True)


def test_executables_exist_and_import():
    scripts = _console_scripts()
    assert {"flexmb_node", "flexmb_player", "flexmb"} <= set(scripts)
    for name, target in scripts.items():
        module, func = target.split(":")
        assert callable(getattr(importlib.import_module(module), func)), f"{name} = {target}"


def test_default_launch_starts_twin_and_player_with_declared_parameters():
    from ros2_node.params import SPECS
    from flexmb_io.topics import DEFAULT_NODE_NAME

    defaults, actions = evaluate(load_launch_file(LAUNCH), scene=SCENE)
    assert defaults["mode"] == "realtime" and defaults["play"] == "true" and defaults["namespace"] == ""
    nodes = _nodes(actions)
    assert set(nodes) == {"flexmb_node", "flexmb_player"}
    assert set(nodes) <= set(_console_scripts())
    assert all(n.kwargs["package"] == "flexmb" for n in nodes.values())
    twin = nodes["flexmb_node"].kwargs
    assert twin["name"] == DEFAULT_NODE_NAME and "namespace" not in twin
    params = {k: v for p in twin["parameters"] for k, v in p.items()}
    assert params == {"scene": SCENE, "mode": "realtime"}
    declared = {s.name: s for s in SPECS}
    assert set(params) <= set(declared)
    assert params["mode"] in declared["mode"].choices
    # the player's command line is one `flexmb play` accepts, aimed at the twin
    from flexmb.cli import build_parser
    args = build_parser().parse_args(["play", *nodes["flexmb_player"].kwargs["arguments"]])
    assert (args.scene, args.twin, args.mode, args.until) == (SCENE, DEFAULT_NODE_NAME, "realtime", 20.0)
    assert not any(a.kind == "RegisterEventHandler" for a in actions)


def test_namespace_record_and_stop_after_play():
    _, actions = evaluate(load_launch_file(LAUNCH), scene=SCENE, namespace="/robot1", mode="lockstep",
                          until="0.5", record="/tmp/bag", stop_after_play="true")
    nodes = _nodes(actions)
    twin = nodes["flexmb_node"].kwargs
    assert twin["namespace"] == "robot1"
    assert twin["parameters"] == [{"scene": SCENE, "mode": "lockstep", "record": "/tmp/bag"}]
    from flexmb.cli import build_parser
    args = build_parser().parse_args(["play", *nodes["flexmb_player"].kwargs["arguments"]])
    assert (args.twin, args.mode, args.until) == ("robot1/flexmb_twin", "lockstep", 0.5)
    [handler] = [a for a in actions if a.kind == "RegisterEventHandler"]
    on_exit = handler.args[0]
    assert on_exit.kwargs["target_action"] is nodes["flexmb_player"]
    assert on_exit.kwargs["on_exit"][0].kwargs["event"].kind == "Shutdown"


def test_twin_alone_and_bad_flag():
    module = load_launch_file(LAUNCH)
    _, actions = evaluate(module, scene=SCENE, play="false")
    assert set(_nodes(actions)) == {"flexmb_node"}
    with pytest.raises(ValueError, match=r"launch argument 'play': expected true or false, got 'maybe'"):
        evaluate(module, scene=SCENE, play="maybe")


def test_real_launch_builds_the_description():
    """Where ROS 2's launch is installed (not on PyPI), the file builds a real description."""
    pytest.importorskip("launch")
    pytest.importorskip("launch_ros")
    spec = importlib.util.spec_from_file_location("twin_launch", LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    names = {a.name for a in description.entities if type(a).__name__ == "DeclareLaunchArgument"}
    assert names == {"scene", "namespace", "mode", "play", "until", "stop_after_play", "record"}


def test_package_metadata_agrees_with_pyproject():
    version = re.search(r'^version\s*=\s*"([^"]+)"', (ROOT / "pyproject.toml").read_text(), re.M).group(1)
    for xml in (PKG / "package.xml", ROOT / "ros" / "tf2_msgs" / "package.xml"):
        root = ET.parse(xml).getroot()
        assert root.get("format") == "3", xml
    root = ET.parse(PKG / "package.xml").getroot()
    assert root.findtext("name") == "flexmb" and root.findtext("version") == version
    assert root.find("export/build_type").text == "ament_python"
    deps = {e.text for e in root.findall("exec_depend")}
    # every interface package ros2_node imports or names a type of (its topic table in flexmb_io) is declared
    used = set()
    for path in [*(ROOT / "ros2_node").rglob("*.py"), *(ROOT / "flexmb_io").rglob("*.py")]:
        used |= set(re.findall(r'(?:from |import |")([a-z0-9_]+_(?:msgs|srvs|interfaces))[./]', path.read_text()))
    assert {"flexmb_msgs", "tf2_msgs", "sensor_msgs"} <= used
    assert used <= deps, f"ros/flexmb/package.xml lacks <exec_depend> of {sorted(used - deps)}"
    assert (PKG / "resource" / "flexmb").is_file()
    assert "install_scripts=$base/lib/flexmb" in (PKG / "setup.cfg").read_text()
