"""Read a twin recording: a rosbag2 directory (``metadata.yaml`` + ``*.mcap``) or a bare ``.mcap``.

Messages are decoded with the ``ros2msg`` schemas embedded in the file (``mcap_ros2``), so custom
``flexmb_msgs`` types need no ROS install. The scene travels as the attachment ``scene.yaml`` and
the run's settings as the metadata record ``flexmb`` (written by ``ros2_node.bag.recorder``).
A file cut short (a killed recorder) is read up to its last complete record.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from flexmb_core.errors import FlexmbError

SCENE_ATTACHMENT = "scene.yaml"
METADATA_NAME = "flexmb"


class RecordingError(FlexmbError):
    """A path that is not a readable twin recording."""


@dataclass
class RecordedMessage:
    """One decoded message. ``stamp`` (s): the header stamp when the type has one (for
    MarkerArray and TFMessage, their first element's), else the ``/clock`` value, else the MCAP
    log time."""

    topic: str
    type: str
    stamp: float
    msg: Any


def _stamp(msg: Any, log_time_ns: int) -> float:
    header = getattr(msg, "header", None)
    for name in ("markers", "transforms"):           # arrays of stamped elements
        items = getattr(msg, name, None)
        if header is None and items:
            header = items[0].header
    if header is not None:
        st = header.stamp
        return st.sec + 1e-9 * st.nanosec
    clock = getattr(msg, "clock", None)
    if clock is not None:
        return clock.sec + 1e-9 * clock.nanosec
    return 1e-9 * log_time_ns


class Recording:
    """A recording on disk.

    Parameters
    ----------
    path
        A rosbag2 directory or an ``.mcap`` file.

    Raises
    ------
    RecordingError
        When the path is neither, or the directory holds no ``.mcap`` file.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.files = self._files(self.path)
        self.truncated = False            # set when a file ended inside a record

    @staticmethod
    def _files(path: Path) -> list[Path]:
        if path.is_file():
            if path.suffix != ".mcap":
                raise RecordingError(f"{path}: not an MCAP file (expected *.mcap or a rosbag2 directory)")
            return [path]
        if not path.is_dir():
            raise RecordingError(f"{path}: no such file or directory (expected a rosbag2 directory or *.mcap)")
        meta = path / "metadata.yaml"
        files: list[Path] = []
        if meta.is_file():
            import yaml

            info = (yaml.safe_load(meta.read_text()) or {}).get("rosbag2_bagfile_information", {})
            # the order of relative_file_paths is the recording order of split bags
            files = [path / f for f in info.get("relative_file_paths", []) if (path / f).is_file()]
        if not files:
            files = sorted(path.glob("*.mcap"))
        if not files:
            raise RecordingError(f"{path}: no .mcap file in this directory (a rosbag2 recording has "
                                 "metadata.yaml and one or more *.mcap)")
        return files

    def _readers(self):
        """(file, reader, summary) per file: a seeking reader when the summary is readable, else a
        reader that walks the records from the start (a file cut short has no footer)."""
        from mcap.exceptions import McapError
        from mcap.reader import NonSeekingReader, SeekingReader

        for f in self.files:
            with open(f, "rb") as stream:
                reader = SeekingReader(stream)
                try:
                    summary = reader.get_summary()
                except (McapError, ValueError, StopIteration):
                    summary = None
                if summary is None:
                    stream.seek(0)
                    reader = NonSeekingReader(stream)
                yield f, reader, summary

    def _walk(self, f: Path, records):
        """Iterate ``records``, stopping quietly where a damaged or unfinished record begins."""
        from mcap.exceptions import McapError

        try:
            yield from records
        except (McapError, ValueError) as exc:
            if not self.truncated:
                warnings.warn(f"{f}: read up to a damaged or unfinished record ({exc})", stacklevel=3)
            self.truncated = True

    def scene_text(self) -> str | None:
        """The attached scene YAML, or None."""
        for f, reader, _ in self._readers():
            for att in self._walk(f, reader.iter_attachments()):
                if att.name == SCENE_ATTACHMENT:
                    return bytes(att.data).decode("utf-8")
        return None

    def metadata(self) -> dict[str, dict[str, str]]:
        """Every metadata record, by name (the recorder writes ``flexmb``)."""
        out: dict[str, dict[str, str]] = {}
        for f, reader, _ in self._readers():
            for m in self._walk(f, reader.iter_metadata()):
                out[m.name] = dict(m.metadata)
        return out

    def channels(self) -> dict[str, str]:
        """Topic → ROS type of every channel (from the summary; a file without one is walked)."""
        out: dict[str, str] = {}
        for f, reader, summary in self._readers():
            if summary is not None:
                pairs = ((ch.topic, summary.schemas.get(ch.schema_id)) for ch in summary.channels.values())
            else:
                walk = self._walk(f, reader.iter_messages(log_time_order=False))
                pairs = ((ch.topic, schema) for schema, ch, _ in walk)
            for topic, schema in pairs:
                out.setdefault(topic, schema.name if schema is not None else "")
        return out

    def messages(self, topics: set[str] | None = None) -> Iterator[RecordedMessage]:
        """Decoded messages in file order (the recorder writes in time order), optionally only
        those of ``topics``. Messages whose schema is not ``ros2msg`` are skipped."""
        from mcap_ros2.decoder import DecoderFactory

        for f, reader, _ in self._readers():
            factory = DecoderFactory()         # it caches by schema id, which is per file
            decoders: dict[int, Any] = {}
            for schema, channel, message in self._walk(f, reader.iter_messages(topics=topics, log_time_order=False)):
                if channel.id not in decoders:
                    decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
                decode = decoders[channel.id]
                if decode is None:
                    continue                          # not ROS 2 CDR (e.g. a foreign JSON channel)
                msg = decode(message.data)
                yield RecordedMessage(channel.topic, schema.name, _stamp(msg, message.log_time), msg)
