"""The node's log written by a thread of its own: a sink that blocks (a pipe nobody reads) stalls
no caller, the lines it could not take are counted, and the others come out in order."""

from __future__ import annotations

import os

from ros2_node.logsink import DeferredLogger


class _PipeLogger:
    """Writes each line to a real pipe with a blocking write, as rcutils writes to stderr."""

    def __init__(self, fd: int):
        self.fd = fd

    def _line(self, level: str, text: str) -> None:
        os.write(self.fd, f"[{level}] {text}\n".encode())

    def debug(self, text): self._line("debug", text)
    def info(self, text): self._line("info", text)
    def warning(self, text): self._line("warning", text)
    def error(self, text): self._line("error", text)


def test_a_pipe_nobody_reads_blocks_no_caller_and_the_overflow_is_counted():
    r, w = os.pipe()
    filled = _fill(w)                     # the reader went away with its 64 kB unread
    log = DeferredLogger(_PipeLogger(w), capacity=16, fd=w)
    lines = 2000
    for i in range(lines):                # would block at once if the caller wrote itself
        log.warning(f"{i:6d} " + "x" * 90)
    assert lines - 16 - 1 <= log.dropped < lines     # the queue's 16, and the one waiting for the sink
    os.read(r, 8000)                                 # the reader takes two pages: lines go out again
    assert log.close(timeout=2.0) is True
    text = _read_all(r)[filled - 8000:].decode(errors="replace").splitlines()
    numbers = [int(line.split()[1]) for line in text if line.startswith("[warning]")]
    assert numbers[0] == 0 and numbers == sorted(numbers) and len(numbers) + log.dropped == lines


def test_closing_with_the_sink_still_blocked_returns_and_counts_the_rest():
    r, w = os.pipe()
    _fill(w)
    log = DeferredLogger(_PipeLogger(w), capacity=16, fd=w)
    for i in range(10):
        log.warning(f"line {i}")
    assert log.close(timeout=0.3) is False and log.dropped == 10


def _fill(fd: int) -> int:
    """Fill the pipe to its capacity; returns the bytes written."""
    os.set_blocking(fd, False)
    n = 0
    try:
        while True:
            n += os.write(fd, b"." * 1000)
    except BlockingIOError:
        pass
    os.set_blocking(fd, True)
    return n


def _read_all(fd: int) -> bytes:
    """What the pipe holds once the writer has had a moment to finish its queue."""
    import select
    out = bytearray()
    while select.select([fd], [], [], 0.5)[0]:
        chunk = os.read(fd, 1 << 16)
        if not chunk:                     # the writer closed it
            break
        out += chunk
    return bytes(out)


def test_lines_keep_their_order_and_level_and_close_writes_them_all():
    r, w = os.pipe()
    log = DeferredLogger(_PipeLogger(w), fd=w)
    log.info("one")
    log.warning("two")
    log.error("three")
    log.debug("four")
    assert log.close(timeout=5.0) is True and log.dropped == 0
    os.close(w)
    assert _read_all(r).decode().splitlines() == ["[info] one", "[warning] two", "[error] three", "[debug] four"]


def test_a_long_line_is_cut_below_a_pipe_page():
    from ros2_node.logsink import MAX_LINE

    r, w = os.pipe()
    log = DeferredLogger(_PipeLogger(w), fd=w)
    log.warning("Δ" * 5000)
    assert log.close(timeout=5.0) is True
    os.close(w)
    line = _read_all(r).decode().splitlines()[0]
    assert line == "[warning] " + "Δ" * MAX_LINE + "…" and len(line.encode()) < 4096 - 100
