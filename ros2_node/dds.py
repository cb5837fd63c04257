"""Where the twin's DDS traffic may go: ``discovery_range`` ``localhost`` (default) or ``subnet``.

``localhost`` keeps every DDS socket of the process on 127.0.0.1: it installs the Fast DDS profile
``fastdds_loopback.xml`` (UDP on 127.0.0.1 and shared memory, no multicast, discovery by unicast to
127.0.0.1) and leaves rmw's automatic range at ``SUBNET`` so that rmw does not add its own
localhost setup — which, measured with rmw_fastrtps in ROS 2 Kilted, opens one socket on 0.0.0.0
and one on the LAN address besides the profile's. Processes on this machine still discover the twin
whatever their own range. A profile the user already set (``FASTDDS_DEFAULT_PROFILES_FILE``) is
respected; the range is then rmw's ``LOCALHOST`` (nothing leaves, though sockets may be bound wider).

``subnet`` is the opt-in for a controller on another machine: ROS 2's default discovery on the
local network, with a warning — the PyPI Fast DDS has no DDS-Security plugins, so the twin's topics
are open to every host that can reach it (a full ROS 2 install can run SROS2).

Resolution order: the ``--discovery-range`` flag; ``FLEXMB_DISCOVERY_RANGE``; the user's
``ROS_AUTOMATIC_DISCOVERY_RANGE`` (``SUBNET``/``SYSTEM_DEFAULT`` → subnet, ``LOCALHOST`` →
localhost); else localhost. The result is exported as ``FLEXMB_DISCOVERY_RANGE`` so the processes
``flexmb demo`` starts resolve the same. Call :func:`configure` before ``rclpy.init``.
"""

from __future__ import annotations

import os
import socket
import struct
from pathlib import Path

from flexmb_core.errors import FlexmbError

RANGES = ("localhost", "subnet")
PROFILE = Path(__file__).with_name("fastdds_loopback.xml")
SUBNET_WARNING = ("discovery_range subnet: DDS discovery and the twin's topics reach every host on the local "
                  "network, without authentication or encryption (this pip install of ROS 2 has no DDS-Security; "
                  "use SROS2 with a full ROS 2 install, or keep the default localhost)")


def resolve(flag: str | None = None, env: dict | None = None) -> str:
    """The discovery range to use (module docstring); raises FlexmbError on a bad value."""
    env = os.environ if env is None else env
    for value, where in ((flag, "--discovery-range"), (env.get("FLEXMB_DISCOVERY_RANGE"), "FLEXMB_DISCOVERY_RANGE")):
        if value:
            v = value.strip().lower()
            if v not in RANGES:
                raise FlexmbError(f"{where}: expected one of {list(RANGES)}, got {value[:40]!r}")
            return v
    ros = (env.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "").strip().upper()
    return "subnet" if ros in ("SUBNET", "SYSTEM_DEFAULT") else "localhost"


def configure(flag: str | None = None, env: dict | None = None) -> tuple[str, str]:
    """Set the environment of this process (and its children) for the resolved range.

    Returns ``(range, note)``: the note is a warning to log ("" when there is nothing to say).
    """
    env = os.environ if env is None else env
    rng = resolve(flag, env)
    env["FLEXMB_DISCOVERY_RANGE"] = rng
    if rng == "subnet":
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
        return rng, SUBNET_WARNING
    if env.get("FASTDDS_DEFAULT_PROFILES_FILE") and env.get("FASTDDS_DEFAULT_PROFILES_FILE") != str(PROFILE):
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        return rng, (f"discovery_range localhost with your FASTDDS_DEFAULT_PROFILES_FILE "
                     f"({env['FASTDDS_DEFAULT_PROFILES_FILE']}): rmw's LOCALHOST range keeps traffic on this machine; "
                     "which addresses the sockets bind to is up to your profile")
    env["FASTDDS_DEFAULT_PROFILES_FILE"] = str(PROFILE)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"      # the profile confines it (module docstring)
    return rng, ""


def bound_addresses(pid: int | str = "self") -> list[tuple[str, str, int]]:
    """``(protocol, address, port)`` of every IPv4 UDP/TCP socket the process holds (Linux; [] elsewhere)."""
    try:
        inodes = set()
        for fd in os.listdir(f"/proc/{pid}/fd"):
            try:
                link = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if link.startswith("socket:["):
                inodes.add(link[8:-1])
        out = []
        for proto in ("udp", "tcp"):
            for line in Path(f"/proc/{pid}/net/{proto}").read_text().splitlines()[1:]:
                f = line.split()
                if f[9] in inodes:
                    ip, port = f[1].split(":")
                    out.append((proto, socket.inet_ntoa(struct.pack("<I", int(ip, 16))), int(port, 16)))
        return out
    except OSError:
        return []


def beyond_loopback(pid: int | str = "self") -> list[str]:
    """The process's sockets bound to anything but 127.0.0.0/8, as ``proto address:port``."""
    return [f"{p} {a}:{port}" for p, a, port in bound_addresses(pid) if not a.startswith("127.")]
