"""Read a twin recording for viewing: :class:`flexmb_io.bag.reader.BagReader` (rosbag2 directory
or bare ``.mcap``, decoded with the embedded ``ros2msg`` schemas, a file cut short read up to its
last complete record) plus what the viewer needs on top: each message's header stamp.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from flexmb_core.errors import FlexmbError


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
        from ..bag.reader import BagReader
        from ..bag.writer import BagError

        self.path = Path(path)
        try:
            self._bag = BagReader(self.path)
        except BagError as exc:
            raise RecordingError(str(exc)) from None
        self.truncated = self._bag.truncated      # the file ended inside a record
        if self.truncated:
            warnings.warn(f"{self._bag.file}: read up to a damaged or unfinished record ({self._bag.problem})",
                          stacklevel=2)

    def scene_text(self) -> str | None:
        """The attached scene YAML, or None."""
        return self._bag.scene_text()

    def metadata(self) -> dict[str, dict[str, str]]:
        """Every metadata record, by name (the recorder writes ``flexmb``)."""
        return dict(self._bag.metadata)

    def channels(self) -> dict[str, str]:
        """Topic → ROS type of every channel."""
        return self._bag.topics()

    def messages(self, topics: set[str] | None = None) -> Iterator[RecordedMessage]:
        """Decoded messages in file order (the recorder writes in time order), optionally only
        those of ``topics``. Channels that are not ROS 2 CDR are skipped."""
        from ..bag.writer import BagError

        skipped: set[str] = set()
        for m in self._bag.messages(topics):
            if m.topic in skipped:
                continue
            try:
                msg = m.decode()
            except BagError:
                skipped.add(m.topic)              # e.g. a foreign JSON channel
                continue
            yield RecordedMessage(m.topic, m.type, _stamp(msg, m.log_time_ns), msg)
