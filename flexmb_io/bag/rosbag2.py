"""The rosbag2 side of a recording: ``metadata.yaml`` (format version 9, storage ``mcap``).

``ros2 bag info``/``play``, rosbags and rerun find a bag's files, topics, types, offered QoS and
message counts here. The recorder rewrites the file atomically (temporary file + rename) at start,
after flushed chunks (at most once a second) and on close, so after a crash it describes at most
what the ``.mcap`` holds up to its last complete chunk (``flexmb bag recover`` rewrites it exactly).

The text is emitted by hand (block style, every string double-quoted) instead of through a YAML
library: it is rewritten several times a second in the twin's time loop.
"""

from __future__ import annotations

import functools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

METADATA_FILE = "metadata.yaml"
VERSION = 9                    # rosbag2 metadata format of Jazzy/Kilted (rosbags reads ≤ 9)
ROS_DISTRO = "kilted"
_INFINITE = {"sec": 9223372036, "nsec": 854775807}   # rmw's "default" duration, as ros2 bag writes it


@dataclass(frozen=True)
class OfferedQos:
    """The QoS profile the twin's publishers offer (``ros2 bag play`` re-offers it)."""

    history: str = "keep_last"           # keep_last | keep_all
    depth: int = 10
    reliability: str = "reliable"        # reliable | best_effort
    durability: str = "volatile"         # volatile | transient_local

    def as_dict(self) -> dict:
        return {"history": self.history, "depth": int(self.depth), "reliability": self.reliability,
                "durability": self.durability, "deadline": dict(_INFINITE), "lifespan": dict(_INFINITE),
                "liveliness": "automatic", "liveliness_lease_duration": dict(_INFINITE),
                "avoid_ros_namespace_conventions": False}


def qos_yaml(qos: OfferedQos) -> str:
    """The offered QoS as the YAML list ``ros2 bag`` stores in each MCAP channel's metadata
    (key ``offered_qos_profiles``); rosbags matches it against ``metadata.yaml``."""
    q = qos.as_dict()
    lines = [f"- history: {q['history']}", f"  depth: {q['depth']}", f"  reliability: {q['reliability']}",
             f"  durability: {q['durability']}"]
    for k in ("deadline", "lifespan"):
        lines += [f"  {k}:", f"    sec: {q[k]['sec']}", f"    nsec: {q[k]['nsec']}"]
    lines += [f"  liveliness: {q['liveliness']}", "  liveliness_lease_duration:",
              f"    sec: {q['liveliness_lease_duration']['sec']}", f"    nsec: {q['liveliness_lease_duration']['nsec']}",
              "  avoid_ros_namespace_conventions: false"]
    return "\n".join(lines)


@dataclass
class TopicInfo:
    """One topic of a bag: name, ROS type, RIHS01 type hash (may be empty) and message count."""

    name: str
    type: str
    type_hash: str = ""
    count: int = 0


@dataclass
class BagInfo:
    """What ``metadata.yaml`` says about a bag of one ``.mcap`` file."""

    file_name: str
    topics: list[TopicInfo] = field(default_factory=list)
    start_ns: int = 0
    end_ns: int = 0
    qos: OfferedQos = field(default_factory=OfferedQos)
    custom_data: dict[str, str] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics)

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns) if self.message_count else 0


@functools.lru_cache(maxsize=None)
def type_hash(type_name: str, schema: str) -> str:
    """RIHS01 hash of a type from its ``ros2msg`` schema text, as ``ros2 bag`` records it
    (computed with rosbags, which matches rosidl's); ``""`` when rosbags is not installed.

    A wrong hash makes rosbags refuse the bag, so the schema must be the one written in the file.
    """
    try:
        from rosbags.typesys import Stores, get_typestore, get_types_from_msg
    except ImportError:          # pragma: no cover - rosbags is in the 'record' extra
        return ""
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(schema, type_name))
    return store.hash_rihs01(type_name)


def _q(s: str) -> str:
    return json.dumps(s, ensure_ascii=False)    # a JSON string is a YAML double-quoted scalar


def render(info: BagInfo) -> str:
    """The ``metadata.yaml`` text of ``info``."""
    n, start, dur = info.message_count, info.start_ns if info.message_count else 0, info.duration_ns
    qos = info.qos.as_dict()
    out = ["rosbag2_bagfile_information:",
           f"  version: {VERSION}",
           "  storage_identifier: mcap",
           "  duration:",
           f"    nanoseconds: {dur}",
           "  starting_time:",
           f"    nanoseconds_since_epoch: {start}",
           f"  message_count: {n}",
           "  topics_with_message_count:" + ("" if info.topics else " []")]
    for t in info.topics:
        out += ["    - topic_metadata:",
                f"        name: {_q(t.name)}",
                f"        type: {_q(t.type)}",
                "        serialization_format: cdr",
                "        offered_qos_profiles:",
                f"          - history: {qos['history']}",
                f"            depth: {qos['depth']}",
                f"            reliability: {qos['reliability']}",
                f"            durability: {qos['durability']}"]
        for k in ("deadline", "lifespan"):
            out += [f"            {k}:", f"              sec: {qos[k]['sec']}", f"              nsec: {qos[k]['nsec']}"]
        out += [f"            liveliness: {qos['liveliness']}",
                "            liveliness_lease_duration:",
                f"              sec: {qos['liveliness_lease_duration']['sec']}",
                f"              nsec: {qos['liveliness_lease_duration']['nsec']}",
                "            avoid_ros_namespace_conventions: false",
                f"        type_description_hash: {_q(t.type_hash)}",
                f"      message_count: {t.count}"]
    out += ['  compression_format: ""',
            '  compression_mode: ""',
            "  relative_file_paths:",
            f"    - {_q(info.file_name)}",
            "  files:",
            f"    - path: {_q(info.file_name)}",
            "      starting_time:",
            f"        nanoseconds_since_epoch: {start}",
            "      duration:",
            f"        nanoseconds: {dur}",
            f"      message_count: {n}"]
    if info.custom_data:
        out.append("  custom_data:")
        out += [f"    {_q(k)}: {_q(v)}" for k, v in info.custom_data.items()]
    else:
        out.append("  custom_data: ~")
    out.append(f"  ros_distro: {ROS_DISTRO}")
    return "\n".join(out) + "\n"


def write(directory: Path, info: BagInfo) -> None:
    """Write ``directory/metadata.yaml`` atomically (readers never see a half-written file)."""
    path = Path(directory) / METADATA_FILE
    tmp = path.with_name(METADATA_FILE + ".tmp")
    tmp.write_text(render(info), encoding="utf-8")
    os.replace(tmp, path)


def read(directory: Path) -> dict:
    """The ``rosbag2_bagfile_information`` mapping of ``directory/metadata.yaml``.

    Raises
    ------
    FileNotFoundError
        When the directory has no ``metadata.yaml``.
    ValueError
        When the file is not a rosbag2 metadata file.
    """
    import yaml

    path = Path(directory) / METADATA_FILE
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: not a rosbag2 metadata file (not YAML text: {str(exc).splitlines()[0][:120]})") from None
    if not isinstance(data, dict) or not isinstance(data.get("rosbag2_bagfile_information"), dict):
        raise ValueError(f"{path}: no 'rosbag2_bagfile_information' mapping (not a rosbag2 metadata file)")
    return data["rosbag2_bagfile_information"]
