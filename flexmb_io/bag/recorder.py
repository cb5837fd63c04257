"""Record the twin to a rosbag2 directory with one ROS 2 MCAP file (no rclpy needed).

``flexmb node --mcap`` and ``flexmb run --mcap`` both write through :class:`BagRecorder`, with the
topic names and types of :mod:`flexmb_io.topics` and the messages of
:mod:`flexmb_io.messages`, so their bags are interchangeable. The bag runs on simulated time:
every message's log time and publish time is the twin's simulated time in ns.

Layout::

    OUT/metadata.yaml       rosbag2 metadata (version 9, storage mcap), rewritten after every chunk
    OUT/OUT_0.mcap          profile ros2, cdr messages, ros2msg schemas (flexmb_msgs included),
                            zstd-compressed chunks of at most ``chunk_seconds`` of simulated time

and inside the MCAP file, written first (so even a killed recording is self-describing):

- attachment ``scene.yaml``: the scene text as it was loaded;
- metadata record ``flexmb``: ``version`` (flexmb), ``scene`` (its name), ``scene_sha256`` (of the
  attached text), ``scene_file``, ``node_name``, ``recorder``, ``chunk_seconds``, ``created``
  (UTC wall clock) and the caller's ``settings``, every value a string (non-strings as JSON).
  :mod:`flexmb_io.bag.replay` reads ``solver`` (the effective ``SolverSpec`` as a JSON mapping),
  ``runner_options`` (``RunnerOptions`` as a JSON mapping) and, for offline runs, ``until``.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
from pathlib import Path
from typing import Any

from . import writer as _w
from .defaults import CHUNK_MESSAGES, CHUNK_SECONDS
from .rosbag2 import OfferedQos
from .writer import BagError, BagWriter
from ..wire import make, serializer

SCENE_ATTACHMENT = "scene.yaml"
METADATA_NAME = "flexmb"


def flexmb_version() -> str:
    """The installed flexmb version (the package metadata, else ``flexmb_core.__version__``)."""
    try:
        from importlib.metadata import version

        return version("flexmb")
    except Exception:                       # pragma: no cover - running from a bare checkout
        import flexmb_core

        return flexmb_core.__version__


def scene_sha256(text: str) -> str:
    """sha256 (hex) of a scene's UTF-8 text — what ``bags/manifest.yaml`` and the bag record."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def setting_string(value: Any) -> str:
    """A settings value as an MCAP metadata string: strings as they are, anything else as JSON
    (dataclasses as mappings; ``inf`` as ``Infinity``, which :func:`json.loads` reads back)."""
    if isinstance(value, str):
        return value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    return json.dumps(value, sort_keys=True, default=str)


class BagRecorder:
    """Write the twin's messages to a new rosbag2/MCAP directory.

    Parameters
    ----------
    out_dir
        The bag directory to create (must not exist, or be empty).
    scene_path
        The scene file the twin loaded (recorded as ``scene_file``).
    scene_text
        The scene YAML text, attached as ``scene.yaml``; ``None`` (or ``scene_path`` itself, e.g.
        ``Scene.source``) reads ``scene_path``. Anything else must be the text of a scene: a
        replay rebuilds the twin from it.
    settings
        Run settings stored in the ``flexmb`` metadata record (values converted with
        :func:`setting_string`). Keys read back by ``flexmb replay``: ``solver`` (the effective
        ``SolverSpec``), ``runner_options`` (``RunnerOptions``), ``until`` (offline runs).
    node_name
        The twin's node name (private topics resolve under it).
    chunk_seconds
        Simulated time (s) after which the open chunk is closed and the file flushed; a killed
        recorder loses at most this much. Chunks also close every ``chunk_messages`` messages.
    compression
        Chunk compression: ``zstd``, ``lz4`` or ``none``.
    chunk_messages
        Message count after which the open chunk is closed.
    qos_depth
        History depth written as the offered QoS of every topic (reliable, volatile, keep-last).

    Raises
    ------
    BagError
        When ``out_dir`` exists and is not empty, or ``scene_text`` is not a scene's YAML text.

    Examples
    --------
    >>> with BagRecorder("out", scene_path="s.yaml", scene_text=text, settings={"dt": 1e-3}) as rec:
    ...     rec.write("/joint_states", "sensor_msgs/msg/JointState", joint_state(sample), sample.t)
    """

    def __init__(self, out_dir, *, scene_path: str, scene_text: str | None, settings: dict,
                 node_name: str = "flexmb_twin", chunk_seconds: float = CHUNK_SECONDS, compression: str = "zstd",
                 chunk_messages: int = CHUNK_MESSAGES, qos_depth: int = 10):
        if scene_text is None or scene_text == str(scene_path):
            scene_text = Path(scene_path).read_text(encoding="utf-8")
        name = self._scene_name(scene_text, scene_path)
        self._bag = BagWriter(out_dir, chunk_seconds=chunk_seconds, chunk_messages=chunk_messages,
                              compression=compression, qos=OfferedQos(depth=int(qos_depth)))
        self.path = self._bag.dir
        self.scene_sha256 = scene_sha256(scene_text)
        meta = {"version": flexmb_version(), "scene": name, "scene_sha256": self.scene_sha256,
                "scene_file": str(scene_path), "node_name": node_name, "recorder": "flexmb_io.bag.recorder",
                "chunk_seconds": repr(float(chunk_seconds)),
                "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
        meta.update({str(k): setting_string(v) for k, v in settings.items()})
        self.metadata = meta
        self._bag.add_attachment(SCENE_ATTACHMENT, scene_text.encode("utf-8"), "application/yaml")
        self._bag.add_metadata(METADATA_NAME, meta)
        self._channels: dict[str, _w.Channel] = {}

    @staticmethod
    def _scene_name(text: str, scene_path: str) -> str:
        from flexmb_core.scene.loader import parse_yaml

        try:
            data = parse_yaml(text)
        except Exception as exc:
            raise BagError(f"scene_text for {scene_path} is not YAML ({exc})") from None
        if not isinstance(data, dict) or "name" not in data:
            raise BagError(f"scene_text for {scene_path} is not a scene (expected the YAML text with a "
                           f"'name' key, got {text[:60]!r}); pass the file's content, not its path")
        return str(data["name"])

    @property
    def closed(self) -> bool:
        return self._bag.closed

    @property
    def message_count(self) -> int:
        return self._bag.messages

    def declare(self, topic: str, type_name: str) -> None:
        """Register ``topic`` now (schema, channel, type hash, serializer) instead of at its first
        message: the first use costs a few ms, which a 1 kHz loop should not pay mid-run.

        Raises
        ------
        BagError
            When the topic was recorded with another type.
        """
        self._channels[topic] = self._bag.channel(topic, type_name)
        serializer(type_name)

    def write(self, topic: str, type_name: str, msg, t_sim: float, t_arrival: float | None = None) -> None:
        """Record one message (serialized here; :meth:`write_cdr` records bytes already serialized).

        Parameters
        ----------
        topic
            Resolved topic name (``/flexmb_twin/status``, ``/joint_states``, …).
        type_name
            ROS type ``pkg/msg/Type`` of :func:`flexmb_io.wire.typestore`.
        msg
            The message: an object of :mod:`flexmb_io.messages` (:mod:`flexmb_io.wire`'s type store), or
            nested dicts/lists with the ROS field names (missing fields are zero).
        t_sim
            Simulated time (s, ≥ 0): the message's log time and publish time, in ns.
        t_arrival
            A command's arrival in twin time (s, ≥ 0), when it differs from ``t_sim``: the publish
            time instead (what :func:`flexmb_io.bag.lockstep.run_lockstep` passes back as
            ``arrival``; :meth:`flexmb_io.realtime.Stepper._arrival`).

        Raises
        ------
        BagError
            When the recorder is closed, ``t_sim`` is negative or not finite, or the topic was
            recorded with another type.
        """
        if isinstance(msg, dict):
            msg = make(type_name, msg)
        self.write_cdr(topic, type_name, serializer(type_name)(msg), t_sim, t_arrival)

    def write_cdr(self, topic: str, type_name: str, data: bytes, t_sim: float, t_arrival: float | None = None) -> None:
        """Record one message given as its CDR bytes (:func:`flexmb_io.wire.serialize`: what the node
        published). Parameters and errors as :meth:`write`."""
        ch = self._channels.get(topic)
        if ch is None or ch.info.type != type_name:
            ch = self._channels[topic] = self._bag.channel(topic, type_name)
        for t in (t_sim, 0.0 if t_arrival is None else t_arrival):
            if not t >= 0.0 or t == float("inf"):
                raise BagError(f"{topic}: message time must be finite and ≥ 0 s (simulated time), got {t}")
        log_ns = int(round(t_sim * 1e9))
        self._bag.write_cdr(ch, data, log_ns, log_ns if t_arrival is None else int(round(t_arrival * 1e9)))

    def flush(self) -> None:
        """Close the open chunk and flush it to the OS now (also done every ``chunk_seconds``)."""
        self._bag.flush()

    def close(self) -> None:
        """Finish the MCAP file (summary, footer) and write the final ``metadata.yaml``. Idempotent."""
        self._bag.close()

    def __enter__(self) -> "BagRecorder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
