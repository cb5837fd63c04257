"""``flexmb_node`` / ``flexmb_player``, the executables of the ROS package (``flexmb.ros_entry``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from flexmb.ros_entry import node_argv, player_argv

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("argv, expected", [
    # as a launch file starts it: the scene is a parameter
    (["--ros-args", "-r", "__node:=twin", "--params-file", "/tmp/p.yaml"],
     ["node", "", "--ros-args", "-r", "__node:=twin", "--params-file", "/tmp/p.yaml"]),
    # as a user types it: a positional scene and flexmb node flags, then ROS arguments
    (["s.yaml", "--mode", "lockstep", "--ros-args", "-p", "dt:=0.002"],
     ["node", "s.yaml", "--mode", "lockstep", "--ros-args", "-p", "dt:=0.002"]),
    (["--mode", "lockstep"], ["node", "", "--mode", "lockstep"]),
    ([], ["node", ""]),
])
def test_node_argv(argv, expected):
    assert node_argv(argv) == expected


def test_player_drops_ros_arguments():
    assert player_argv(["s.yaml", "--until", "1", "--ros-args", "-r", "__node:=flexmb_player"]) == \
        ["play", "s.yaml", "--until", "1"]


@pytest.mark.ros
def test_node_without_scene_says_which_parameter(dds_env):
    pytest.importorskip("rclpy")
    proc = subprocess.run([sys.executable, "-m", "flexmb.ros_entry", "--ros-args", "-r", "__node:=t"],
                          env=dds_env, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines()[-1] == "flexmb node: parameter 'scene': required (a scene YAML file), got ''"
    assert "Traceback" not in proc.stderr
