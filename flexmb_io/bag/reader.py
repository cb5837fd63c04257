"""Read twin recordings record by record, tolerating files cut short; rebuild a complete bag.

A recording killed with SIGKILL ends inside (or right after) a chunk and has no summary or footer.
:class:`BagReader` scans the MCAP file sequentially, keeps every record that is complete, and stops
at the first one that is not (``truncated`` then says so and ``valid_bytes`` where the good part
ends). A chunk is used only whole (its CRC is checked), so a killed recording yields exactly the
messages of its complete chunks. :func:`recover` writes those into a new, complete bag.

Decoded messages come from ``mcap_ros2``'s decoder built from the schema embedded in the file,
so ``flexmb_msgs`` types need no ROS install.
"""

from __future__ import annotations

import io
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

from . import rosbag2
from .recorder import METADATA_NAME, SCENE_ATTACHMENT
from .writer import BagError, BagWriter

MAGIC = b"\x89MCAP0\r\n"


def obj_to_dict(o):
    """A decoded MCAP message (attribute object) as plain dicts/lists/numbers."""
    if hasattr(o, "__slots__"):
        return {k: obj_to_dict(getattr(o, k)) for k in o.__slots__ if not k.startswith("_")}
    if isinstance(o, (list, tuple)):
        return [obj_to_dict(v) for v in o]
    if isinstance(o, (bytes, bytearray)):
        return list(o)
    return o


@dataclass
class BagMessage:
    """One message: topic, ROS type, log time (ns of simulated time), CDR bytes, publish time (ns; a
    live node's command: its arrival in twin time); ``decode()`` gives the message object (fields as
    attributes)."""

    topic: str
    type: str
    log_time_ns: int
    data: bytes
    channel_id: int
    _decode: Any = field(repr=False, default=None)
    publish_time_ns: int = -1

    @property
    def arrival(self) -> float | None:
        """A command's arrival (s of twin time) when it was recorded apart from its log time, else
        None (apply it at the twin's time): the ``arrival`` of :func:`flexmb_io.twin.apply_message`."""
        p = self.publish_time_ns
        return None if p < 0 or p == self.log_time_ns else p * 1e-9

    @property
    def t(self) -> float:
        """Log time in seconds."""
        return self.log_time_ns * 1e-9

    def decode(self) -> Any:
        return self._decode(self.data)


def find_mcap(path: Path) -> Path:
    """The MCAP file of a bag: ``path`` itself when it is a file, else the (single) file listed in
    the directory's ``metadata.yaml`` or found in it.

    Raises
    ------
    BagError
        When the path does not exist, is not an ``.mcap`` file or holds no / several MCAP files.
    """
    path = Path(path)
    if path.is_file():
        if path.suffix != ".mcap":
            raise BagError(f"{path}: not an MCAP file (expected a rosbag2 directory or *.mcap)")
        return path
    if not path.is_dir():
        raise BagError(f"{path}: no such file or directory (expected a rosbag2 directory or *.mcap)")
    files: list[Path] = []
    if (path / rosbag2.METADATA_FILE).is_file():
        try:
            info = rosbag2.read(path)
            files = [path / f for f in info.get("relative_file_paths", []) if (path / f).is_file()]
        except (ValueError, OSError):
            files = []
    if not files:
        files = sorted(path.glob("*.mcap"))
    if not files:
        raise BagError(f"{path}: no .mcap file in this directory (expected one .mcap file, with metadata.yaml "
                       "in a rosbag2 recording)")
    if len(files) != 1:
        raise BagError(f"{path}: expected one .mcap file in the bag directory, found {[f.name for f in files]}")
    return files[0]


class BagReader:
    """A recording on disk (a rosbag2 directory or a bare ``.mcap``), read once into memory by
    records (small bags; the reference bags are a few MB).

    Parameters
    ----------
    path
        The bag directory or MCAP file.

    Attributes
    ----------
    truncated : bool
        The file ends before its footer (a killed recorder): everything up to the last complete
        record was read.
    valid_bytes : int
        Offset of the end of the last complete record.
    problem : str
        Why reading stopped early ("" for a complete file).

    Raises
    ------
    BagError
        When the path is not a bag, or the file does not start as MCAP.
    """

    def __init__(self, path):
        from mcap.records import Schema

        self.path = Path(path)
        self.file = find_mcap(self.path)
        self.truncated = False
        self.problem = ""
        self.valid_bytes = 0
        self.profile = ""
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Any] = {}
        self.attachments: dict[str, bytes] = {}
        self.attachment_records: list[Any] = []
        self.metadata: dict[str, dict[str, str]] = {}
        self.messages_raw: list[Any] = []        # mcap Message records, file order
        self.chunks = 0
        self.chunk_spans: list[tuple[int, int]] = []   # (first, last) log time (ns) of every complete chunk
        self._scan()
        self._decoders: dict[int, Any] = {}

    # -- scanning --------------------------------------------------------------------------------
    def _scan(self) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.opcode import Opcode
        from mcap.records import Attachment, Channel, Chunk, Footer, Header, Message, Metadata, Schema
        from mcap.stream_reader import breakup_chunk

        data = self.file.read_bytes()
        if data[:8] != MAGIC:
            raise BagError(f"{self.file}: not an MCAP file (bad magic {data[:8]!r})")
        pos, n = 8, len(data)
        self.valid_bytes = pos
        footer = False
        while True:
            if pos == n:
                self._stop(pos, n, "no footer after the last complete record (the recorder was not closed)")
                break
            if pos + 9 > n:
                self._stop(pos, n, "the file ends inside a record header")
                break
            opcode = data[pos]
            (length,) = struct.unpack_from("<Q", data, pos + 1)
            end = pos + 9 + length
            if end > n:
                self._stop(pos, n, f"the file ends inside a record (opcode 0x{opcode:02x}, "
                                   f"{length} bytes, {n - pos - 9} present)")
                break
            body = ReadDataStream(io.BytesIO(data[pos + 9:end]))
            try:
                if opcode == Opcode.HEADER:
                    self.profile = Header.read(body).profile
                elif opcode == Opcode.SCHEMA:
                    s = Schema.read(body)
                    self.schemas[s.id] = s
                elif opcode == Opcode.CHANNEL:
                    c = Channel.read(body)
                    self.channels[c.id] = c
                elif opcode == Opcode.MESSAGE:
                    self.messages_raw.append(Message.read(body, length))
                elif opcode == Opcode.CHUNK:
                    chunk = Chunk.read(body)
                    for rec in breakup_chunk(chunk, validate_crc=True):
                        if isinstance(rec, Schema):
                            self.schemas[rec.id] = rec
                        elif isinstance(rec, Channel):
                            self.channels[rec.id] = rec
                        elif isinstance(rec, Message):
                            self.messages_raw.append(rec)
                    self.chunks += 1
                    self.chunk_spans.append((chunk.message_start_time, chunk.message_end_time))
                elif opcode == Opcode.ATTACHMENT:
                    a = Attachment.read(body)
                    self.attachments[a.name] = bytes(a.data)
                    self.attachment_records.append(a)
                elif opcode == Opcode.METADATA:
                    m = Metadata.read(body)
                    self.metadata[m.name] = dict(m.metadata)
                elif opcode == Opcode.FOOTER:
                    footer = True
                    if Footer.read(body).summary_start == 0:
                        # the writer's provisional end (flexmb_io.bag.writer): readable, but the
                        # recorder never closed the file
                        self._stop(pos, n, "a provisional footer without summary (the recorder was not closed)")
            except Exception as exc:            # a torn record whose length field survived
                self._stop(pos, n, f"damaged record at byte {pos} (opcode 0x{opcode:02x}): {exc}")
                break
            pos = end
            self.valid_bytes = pos
            if footer:
                if data[pos:pos + 8] != MAGIC:
                    self._stop(pos, n, "no closing magic after the footer")
                break

    def _stop(self, pos: int, n: int, why: str) -> None:
        self.truncated = True
        self.problem = f"{why} at byte {pos} of {n}"

    # -- content -----------------------------------------------------------------------------------
    def topics(self) -> dict[str, str]:
        """Topic → ROS type, for every channel seen."""
        return {c.topic: self.schemas[c.schema_id].name for c in self.channels.values()
                if c.schema_id in self.schemas}

    def scene_text(self) -> str | None:
        """The attached scene YAML, or None."""
        raw = self.attachments.get(SCENE_ATTACHMENT)
        if raw is None:
            return None
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise BagError(f"{self.path}: the attached {SCENE_ATTACHMENT} is not UTF-8 text (byte {exc.start}: "
                           "a damaged recording?)") from None

    def settings(self) -> dict[str, str]:
        """The ``flexmb`` metadata record (empty when absent)."""
        return dict(self.metadata.get(METADATA_NAME, {}))

    def setting(self, key: str, default: Any = None, *, as_json: bool = False) -> Any:
        """One ``flexmb`` metadata value, optionally parsed as JSON."""
        v = self.metadata.get(METADATA_NAME, {}).get(key)
        if v is None:
            return default
        return json.loads(v) if as_json else v

    def _decoder(self, channel_id: int):
        dec = self._decoders.get(channel_id)
        if dec is None:
            from mcap_ros2.decoder import DecoderFactory

            ch = self.channels[channel_id]
            dec = DecoderFactory().decoder_for(ch.message_encoding, self.schemas.get(ch.schema_id))
            if dec is None:
                raise BagError(f"{self.file}: topic {ch.topic} is not ROS 2 CDR with a ros2msg schema")
            self._decoders[channel_id] = dec
        return dec

    def messages(self, topics: set[str] | None = None) -> Iterator[BagMessage]:
        """Messages in file order (the recorder writes in time order), optionally only ``topics``."""
        for m in self.messages_raw:
            ch = self.channels.get(m.channel_id)
            if ch is None or (topics is not None and ch.topic not in topics):
                continue
            schema = self.schemas.get(ch.schema_id)
            # the decoder is looked up when a message is decoded, so a channel that is not ROS 2
            # CDR fails (BagError) only for a caller that decodes it
            yield BagMessage(ch.topic, schema.name if schema else "", m.log_time, bytes(m.data), m.channel_id,
                             lambda data, _c=m.channel_id: self._decoder(_c)(data), m.publish_time)

    def counts(self) -> dict[str, int]:
        """Messages per topic."""
        out: dict[str, int] = {}
        for m in self.messages_raw:
            ch = self.channels.get(m.channel_id)
            if ch is not None:
                out[ch.topic] = out.get(ch.topic, 0) + 1
        return out

    def time_range_ns(self) -> tuple[int, int]:
        """(first, last) log time in ns; (0, 0) without messages."""
        if not self.messages_raw:
            return 0, 0
        times = [m.log_time for m in self.messages_raw]
        return min(times), max(times)


def recover(src, out_dir, *, chunk_seconds: float = 0.25,
            edit: Callable[[str, str, bytes], bytes] | None = None) -> BagReader:
    """Write a complete bag at ``out_dir`` from everything readable in ``src`` (a bag or ``.mcap``,
    possibly cut short): attachments, metadata records, schemas, channels and messages, with
    their original log and publish times and bytes. Returns the reader of ``src``.

    ``edit(topic, type_name, cdr)`` may return other CDR bytes for a message (e.g. measurement
    noise added to the outputs of a synthetic recording); None copies every message as it is.

    Raises
    ------
    BagError
        When ``src`` is not a bag or ``out_dir`` exists and is not empty.
    """
    r = BagReader(src)
    out = BagWriter(out_dir, chunk_seconds=chunk_seconds)
    try:
        for a in r.attachment_records:
            out.add_attachment(a.name, bytes(a.data), a.media_type, a.log_time)
        for name, meta in r.metadata.items():
            out.add_metadata(name, meta)
        chans = {}
        for cid, ch in sorted(r.channels.items()):
            schema = r.schemas.get(ch.schema_id)
            if schema is None or schema.encoding != "ros2msg" or ch.message_encoding != "cdr":
                continue
            chans[cid] = out.channel(ch.topic, schema.name, bytes(schema.data).decode("utf-8"))
        for m in r.messages_raw:
            ch = chans.get(m.channel_id)
            if ch is not None:
                data = bytes(m.data)
                out.write_cdr(ch, data if edit is None else edit(ch.info.name, ch.info.type, data), m.log_time,
                              m.publish_time)
    finally:
        out.close()
    return r
