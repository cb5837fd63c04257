"""Nothing leaves loopback (issue 15, item 6): with default settings every DDS socket of the twin
node is bound to 127.0.0.1 (ros2_node/fastdds_loopback.xml), and a client on this machine still
talks to it; the discovery range resolves as documented and subnet warns."""

from __future__ import annotations

import pytest

from flexmb_core.errors import FlexmbError
from ros2_node import dds

from dds_harness import NodeProcess, TwinClient

SCENE = "scenes/stewart_platform_bars.yaml"


def test_every_socket_of_the_node_is_on_loopback_and_a_client_still_talks_to_it(tmp_path, dds_env):
    node = NodeProcess([SCENE, "--mode", "realtime", "--duration", "30", "--quiet"], dds_env, tmp_path / "node.log")
    client = TwinClient()
    try:
        client.wait_for_twin(node)                      # discovery and data over loopback
        client.spin_until(lambda: len(client.statuses()) >= 3, 20, "status messages", node)
        sockets = dds.bound_addresses(node.proc.pid)
        wider = dds.beyond_loopback(node.proc.pid)
    finally:
        client.close()
        node.stop()
    assert sockets, "no socket of the node found (is /proc readable?)"
    assert not wider, f"DDS sockets of the node beyond loopback: {wider} (all: {sockets})"


@pytest.mark.parametrize("flag, env, expected", [
    (None, {}, "localhost"),
    (None, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}, "localhost"),
    (None, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, "subnet"),
    (None, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "FLEXMB_DISCOVERY_RANGE": "localhost"}, "localhost"),
    ("subnet", {"FLEXMB_DISCOVERY_RANGE": "localhost"}, "subnet"),
    ("localhost", {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, "localhost"),
])
def test_discovery_range_resolution(flag, env, expected):
    assert dds.resolve(flag, env) == expected


def test_localhost_installs_the_loopback_profile_and_subnet_warns():
    env: dict = {}
    assert dds.configure(None, env) == ("localhost", "")
    assert env["FASTDDS_DEFAULT_PROFILES_FILE"] == str(dds.PROFILE) and dds.PROFILE.is_file()
    assert env["FLEXMB_DISCOVERY_RANGE"] == "localhost"
    assert dds.configure(None, env) == ("localhost", "")          # a child process resolves the same
    own = {"FASTDDS_DEFAULT_PROFILES_FILE": "/etc/mine.xml"}
    rng, note = dds.configure(None, own)
    assert rng == "localhost" and own["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST" and "/etc/mine.xml" in note
    wide: dict = {}
    rng, note = dds.configure("subnet", wide)
    assert rng == "subnet" and wide["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert "every host on the local network" in note and "SROS2" in note
    assert "FASTDDS_DEFAULT_PROFILES_FILE" not in wide
    with pytest.raises(FlexmbError, match=r"FLEXMB_DISCOVERY_RANGE: expected one of \['localhost', 'subnet'\]"):
        dds.resolve(None, {"FLEXMB_DISCOVERY_RANGE": "internet"})
