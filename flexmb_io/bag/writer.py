"""A rosbag2 directory holding one chunked, compressed ROS 2 MCAP file (already-encoded messages).

:class:`BagWriter` owns the file layout and crash safety; :class:`~flexmb_io.bag.recorder.BagRecorder`
(messages or their CDR bytes) and :func:`~flexmb_io.bag.reader.recover` (raw records) write through it.

Crash safety: a chunk is closed and the file flushed to the operating system every
``chunk_seconds`` of message time, every ``chunk_messages`` messages, or when the chunk exceeds
``chunk_bytes`` — whichever comes first — and ``metadata.yaml`` is then rewritten (at most once a
second of wall time, at once when a topic was added) to describe what is on disk. A killed process therefore loses at most the open chunk; the data before it is
complete records that :class:`~flexmb_io.bag.reader.BagReader` reads and ``flexmb bag recover``
turns back into a complete bag. (Flushing reaches the kernel, which survives the process; it is
not an ``fsync``, which only a power loss would need.)

Readable by the standard readers after a kill: every flush ends the file with a provisional
``DataEnd`` + ``Footer`` (no summary) + magic, written in the same ``pwrite`` as the chunk it
follows; the next flush writes its chunk over that tail. A file cut by SIGKILL is therefore a valid
MCAP up to the last flushed chunk, which ``mcap``, ``mcap-ros2-support`` and ``rosbags`` read by
scanning (there is no summary to seek with). Only a kill inside that one system call (a few µs per
``chunk_seconds``) can leave a torn tail, which ``flexmb bag recover`` repairs. ``close`` writes
the full summary and footer over the tail.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from flexmb_core.errors import FlexmbError

from . import rosbag2
from .rosbag2 import BagInfo, OfferedQos, TopicInfo


class Channel:
    """A registered topic: MCAP channel id, its :class:`TopicInfo` and next sequence number."""

    __slots__ = ("id", "info", "sequence")

    def __init__(self, cid: int, info: TopicInfo):
        self.id, self.info, self.sequence = cid, info, 0


class BagError(FlexmbError, ValueError):
    """A recording cannot be written or read as asked (the message says which path and why)."""


def _compression(name: str):
    from mcap.writer import CompressionType

    table = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE,
             "": CompressionType.NONE}
    if name not in table:
        raise BagError(f"compression must be one of 'zstd', 'lz4', 'none', got {name!r}")
    return table[name]


def _provisional_tail() -> bytes:
    """``DataEnd`` + ``Footer`` without a summary + the closing magic: the smallest end that
    makes the bytes before it a complete MCAP file."""
    from mcap.records import DataEnd, Footer
    from mcap.writer import MCAP0_MAGIC
    from mcap.data_stream import RecordBuilder

    b = RecordBuilder()
    DataEnd(0).write(b)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(b)
    return bytes(b.end()) + MCAP0_MAGIC


class _CommitStream:
    """The stream the ``mcap`` writer writes to: bytes wait in memory until :meth:`commit` writes
    them, followed by a tail, in one ``pwrite`` at the end of the committed data; the next commit
    overwrites that tail. ``tell`` counts committed and pending bytes (the writer's offsets)."""

    def __init__(self, path: Path):
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._committed = 0
        self._pending = bytearray()

    def write(self, data) -> int:
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self._committed + len(self._pending)

    def flush(self) -> None:        # the mcap writer's flush: committing is the owner's decision
        pass

    def commit(self, tail: bytes = b"") -> None:
        """Write the pending bytes and ``tail`` at the end of the committed data (one system call
        unless the kernel writes less)."""
        buf = memoryview(bytes(self._pending) + tail)
        off = self._committed
        while buf:
            n = os.pwrite(self._fd, buf, off)
            buf, off = buf[n:], off + n
        self._committed += len(self._pending)
        self._pending.clear()

    def close(self) -> None:
        """Commit, cut anything beyond the data (a provisional tail) and close."""
        self.commit()
        os.ftruncate(self._fd, self._committed)
        os.close(self._fd)


class BagWriter:
    """Open ``out_dir`` as a new rosbag2 bag and write its MCAP file.

    Parameters
    ----------
    out_dir
        Directory to create. It must not exist, or be empty (a recording is never overwritten).
    chunk_seconds
        Close the open chunk once it spans this much message time (s; the twin's simulated time).
    chunk_messages
        Close the open chunk once it holds this many messages.
    chunk_bytes
        Close the open chunk once its uncompressed size exceeds this (bytes).
    compression
        ``zstd`` (default), ``lz4`` or ``none``.
    qos
        The QoS profile written in ``metadata.yaml`` as offered by every topic.
    custom_data
        String pairs for ``metadata.yaml``'s ``custom_data``.
    metadata_interval
        Least wall-clock time (s) between two rewrites of ``metadata.yaml`` after chunk flushes
        (a rewrite costs ~0.5 ms; it is always rewritten on close).

    Raises
    ------
    BagError
        When ``out_dir`` exists and is not an empty directory, or a parameter is out of range.
    """

    def __init__(self, out_dir, *, chunk_seconds: float = 0.25, chunk_messages: int = 5000,
                 chunk_bytes: int = 1 << 20, compression: str = "zstd", qos: OfferedQos | None = None,
                 custom_data: dict[str, str] | None = None, metadata_interval: float = 1.0):
        from mcap.writer import Writer

        if not chunk_seconds > 0:
            raise BagError(f"chunk_seconds must be > 0 s, got {chunk_seconds}")
        if int(chunk_messages) < 1:
            raise BagError(f"chunk_messages must be ≥ 1, got {chunk_messages}")
        self.dir = Path(out_dir)
        if self.dir.exists() and (not self.dir.is_dir() or any(self.dir.iterdir())):
            raise BagError(f"{self.dir}: already exists and is not an empty directory "
                           "(a recording is never overwritten; choose a new path)")
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise BagError(f"{self.dir}: cannot create the recording's directory ({exc.strerror or exc})") from None
        self.file_name = f"{self.dir.name or 'bag'}_0.mcap"
        self.path = self.dir / self.file_name
        self._chunk_ns = int(round(chunk_seconds * 1e9))
        self._chunk_messages = int(chunk_messages)
        self._stream = _CommitStream(self.path)
        self._tail = _provisional_tail()
        # message indexes are kept (rosbags finds messages through them) although writing them is
        # most of a chunk flush's cost
        self._mcap = Writer(self._stream, chunk_size=int(chunk_bytes), compression=_compression(compression))
        self._mcap.start(profile="ros2", library="flexmb/flexmb_io.bag")
        self._stream.commit(self._tail)
        self.info = BagInfo(self.file_name, qos=qos or OfferedQos(), custom_data=dict(custom_data or {}))
        self._channels: dict[str, Channel] = {}                # topic → channel
        self._schemas: dict[str, int] = {}                     # type → schema id
        self._chunk_start: int | None = None                   # log time of the open chunk's first message
        self._chunk_count = 0
        self.chunks_flushed = 0
        self.messages = 0
        self.closed = False
        self._metadata_interval = float(metadata_interval)
        self._metadata_wall = time.monotonic()
        self._metadata_topics = 0
        rosbag2.write(self.dir, self.info)                     # provisional: no messages yet

    # -- records outside chunks (written and flushed at once) --------------------------------------
    def add_attachment(self, name: str, data: bytes, media_type: str = "application/octet-stream",
                       log_time_ns: int = 0) -> None:
        self._mcap.add_attachment(create_time=0, log_time=int(log_time_ns), name=name, media_type=media_type,
                                  data=bytes(data))
        self._stream.commit(self._tail)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._mcap.add_metadata(name, {str(k): str(v) for k, v in data.items()})
        self._stream.commit(self._tail)

    # -- messages -------------------------------------------------------------------------------
    def channel(self, topic: str, type_name: str, schema: str | None = None) -> Channel:
        """The channel of ``topic`` (registered on first use with the ``ros2msg`` schema of
        ``type_name``, by default the one of :func:`flexmb_io.wire.schema`; a given ``schema``, e.g. a
        recovered bag's own, is hashed as written).

        Raises
        ------
        BagError
            When ``topic`` was registered with another type.
        """
        ch = self._channels.get(topic)
        if ch is not None:
            if ch.info.type != type_name:
                raise BagError(f"{self.path}: topic {topic} is recorded as {ch.info.type}, "
                               f"cannot also write {type_name} on it")
            return ch
        from .. import wire

        text = schema if schema is not None else wire.schema(type_name)
        sid = self._schemas.get(type_name)
        if sid is None:
            sid = self._mcap.register_schema(type_name, "ros2msg", text.encode("utf-8"))
            self._schemas[type_name] = sid
        digest = rosbag2.type_hash(type_name, text) if schema is not None else wire.type_hash(type_name)
        # the channel metadata ros2 bag's MCAP storage writes (rosbags checks it against metadata.yaml)
        meta = {"offered_qos_profiles": rosbag2.qos_yaml(self.info.qos), "topic_type_hash": digest}
        cid = self._mcap.register_channel(topic=topic, message_encoding="cdr", schema_id=sid, metadata=meta)
        ch = Channel(cid, TopicInfo(topic, type_name, digest))
        self._channels[topic] = ch
        self.info.topics.append(ch.info)
        return ch

    def write_cdr(self, channel: Channel, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Append one CDR-encoded message on ``channel`` at ``log_time_ns`` (ns ≥ 0); its publish
        time is ``publish_time_ns``, by default the log time."""
        if self.closed:
            raise BagError(f"{self.path}: the recording is closed")
        channel.sequence += 1
        self._mcap.add_message(channel_id=channel.id, log_time=log_time_ns, data=data,
                               publish_time=log_time_ns if publish_time_ns is None else publish_time_ns,
                               sequence=channel.sequence)
        channel.info.count += 1
        bag = self.info
        self.messages += 1
        if self.messages == 1:
            bag.start_ns = bag.end_ns = log_time_ns
        elif log_time_ns > bag.end_ns:
            bag.end_ns = log_time_ns
        elif log_time_ns < bag.start_ns:
            bag.start_ns = log_time_ns
        if self._chunk_start is None:
            self._chunk_start = log_time_ns
        self._chunk_count += 1
        if log_time_ns - self._chunk_start >= self._chunk_ns or self._chunk_count >= self._chunk_messages:
            self.flush()

    def flush(self) -> None:
        """Close the open chunk and hand everything to the OS; rewrite ``metadata.yaml`` if the
        last rewrite is older than ``metadata_interval`` (wall clock)."""
        if self.closed:
            return
        self._mcap.flush()             # finalizes the chunk (if it holds messages)
        self._stream.commit(self._tail)
        self._chunk_start = None
        self._chunk_count = 0
        self.chunks_flushed += 1
        now = time.monotonic()
        # a new topic is written at once: rosbags reads a killed bag's messages by the topics listed
        # in metadata.yaml (stale counts do not matter to it)
        if now - self._metadata_wall >= self._metadata_interval or len(self.info.topics) != self._metadata_topics:
            rosbag2.write(self.dir, self.info)
            self._metadata_wall = now
            self._metadata_topics = len(self.info.topics)

    def close(self) -> None:
        """Write the MCAP summary and footer and the final ``metadata.yaml``. Idempotent."""
        if self.closed:
            return
        self.closed = True
        try:
            self._mcap.finish()
        finally:
            self._stream.close()
            rosbag2.write(self.dir, self.info)
