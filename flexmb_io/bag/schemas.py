"""ROS 2 message definitions (``ros2msg`` schema text) for the types the twin records.

An MCAP ``ros2msg`` schema is the type's own ``.msg`` text followed by every type it depends on,
each after a line of 80 ``=`` and ``MSG: pkg/Type`` — the form rosbag2, ``mcap_ros2``, rosbags and
rerun decode. The texts come from:

1. ``msgs/msg`` of this repository for ``flexmb_msgs`` (the single source of truth), else the
   installed ``share/flexmb_msgs/msg``;
2. ``msgdefs/<pkg>/msg/<Type>.msg`` next to this module: copies of the standard ROS 2 (Kilted)
   definitions, so recording works without ROS installed. ``python -m flexmb_io.bag.schemas
   --refresh PREFIX`` re-copies them from an ament prefix; a test checks they match the installed
   interface packages.
"""

from __future__ import annotations

import argparse
import functools
import os
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
VENDORED = HERE / "msgdefs"
REPO_MSGS = HERE.parents[1] / "msgs" / "msg"
SEPARATOR = "=" * 80

PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}

# The types the twin writes and reads (inputs and outputs, see flexmb_io.topics).
RECORDED_TYPES = (
    "std_msgs/msg/Float64MultiArray", "flexmb_msgs/msg/ActuatorCommand", "trajectory_msgs/msg/JointTrajectory",
    "sensor_msgs/msg/JointState", "flexmb_msgs/msg/ActuatorState", "geometry_msgs/msg/PoseStamped",
    "visualization_msgs/msg/MarkerArray", "flexmb_msgs/msg/TwinStatus", "rosgraph_msgs/msg/Clock",
    "tf2_msgs/msg/TFMessage",
)


def _split(type_name: str) -> tuple[str, str]:
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise ValueError(f"not a ROS 2 message type: {type_name!r} (expected 'pkg/msg/Type')")


def _ament_prefixes() -> list[Path]:
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return prefixes + [Path(sys.prefix)]


@functools.lru_cache(maxsize=None)
def definition(pkg: str, name: str) -> str:
    """The ``.msg`` text of ``pkg/msg/name``, comments and blank lines removed."""
    candidates = []
    if pkg == "flexmb_msgs":
        candidates.append(REPO_MSGS / f"{name}.msg")
    candidates.append(VENDORED / pkg / "msg" / f"{name}.msg")
    candidates += [p / "share" / pkg / "msg" / f"{name}.msg" for p in _ament_prefixes()]
    for path in candidates:
        if path.is_file():
            return strip_comments(path.read_text())
    raise FileNotFoundError(f"no definition of {pkg}/msg/{name}; looked in "
                            + ", ".join(str(c) for c in candidates))


def strip_comments(text: str) -> str:
    lines = []
    for line in text.splitlines():
        # a '#' inside a string constant's value is not a comment; msg files we use have none
        code = line.split("#", 1)[0].rstrip() if not re.match(r"^\s*string\s+\w+\s*=", line) else line.rstrip()
        if code.strip():
            lines.append(code.strip())
    return "\n".join(lines) + "\n"


def _field_types(pkg: str, text: str) -> list[tuple[str, str]]:
    """Complex field types of a definition, as (pkg, Type)."""
    out = []
    for line in text.splitlines():
        tok = line.split()
        if len(tok) < 2 or "=" in line.split()[1]:
            continue                                           # constants: "int32 X=1"
        base = re.sub(r"\[.*\]$", "", tok[0])
        base = re.sub(r"<=\d+$", "", base)
        if base in PRIMITIVES:
            continue
        if "/" in base:
            out.append(_split(base))
        elif base == "Header":
            out.append(("std_msgs", "Header"))
        else:
            out.append((pkg, base))
    return out


@functools.lru_cache(maxsize=None)
def schema_text(type_name: str) -> str:
    """The ``ros2msg`` schema of ``pkg/msg/Type``: its definition, then its dependencies once each
    (depth first, in order of first use)."""
    pkg, name = _split(type_name)
    main = definition(pkg, name)
    seen: list[tuple[str, str]] = []

    def visit(p: str, n: str) -> None:
        for dep in _field_types(p, definition(p, n)):
            if dep not in seen:
                seen.append(dep)
                visit(*dep)

    visit(pkg, name)
    parts = [main.rstrip("\n")]
    for p, n in seen:
        parts.append(f"{SEPARATOR}\nMSG: {p}/{n}\n{definition(p, n).rstrip(chr(10))}")
    return "\n".join(parts) + "\n"


def dependencies(type_name: str) -> list[str]:
    """Every ``pkg/msg/Type`` the schema of ``type_name`` includes (itself first)."""
    pkg, name = _split(type_name)
    out = [f"{pkg}/msg/{name}"]
    for line in schema_text(type_name).splitlines():
        if line.startswith("MSG: "):
            p, n = _split(line[5:])
            out.append(f"{p}/msg/{n}")
    return out


def refresh(prefix: Path) -> list[Path]:
    """Copy the standard definitions the recorded types need from an ament prefix into msgdefs/."""
    written: list[Path] = []
    deps = dict.fromkeys(d for t in RECORDED_TYPES for d in dependencies(t))
    for dep in deps:
        pkg, name = _split(dep)
        if pkg == "flexmb_msgs":
            continue
        src = prefix / "share" / pkg / "msg" / f"{name}.msg"
        if not src.is_file():
            continue                                           # e.g. tf2_msgs: kept as vendored
        dst = VENDORED / pkg / "msg" / f"{name}.msg"
        dst.parent.mkdir(parents=True, exist_ok=True)
        dst.write_text(src.read_text())
        written.append(dst)
    return written


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="Refresh the vendored standard message definitions.")
    ap.add_argument("--refresh", metavar="PREFIX", type=Path, required=True)
    for path in refresh(ap.parse_args().refresh):
        print(path.relative_to(HERE))
