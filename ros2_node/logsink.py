"""Log lines written by a thread of their own, only when the log's sink can take them.

rclpy's logger writes each line to stderr synchronously (rcutils' console handler) and holds the
GIL while it writes. When stderr is a pipe nobody reads — ``flexmb node … 2>&1 | less`` paused, a
supervisor that reads its child's output only at the end — the write blocks once the pipe's 64 kB
are full, and with it every thread of the node: measured (issue 15), a flood of warnings into such
a pipe froze the twin (no status, sim time stopped, SIGINT ignored) with the writing thread in
``fprintf`` under ``RcutilsLogger.log``; an earlier 2-hour soak, whose publisher thread blocked
there, grew by 7.5 MB a minute.

:class:`DeferredLogger` queues each line (bounded) and returns at once; a daemon thread waits,
without the GIL (``poll``), until the sink can take a line without blocking, then hands it to the
rclpy logger. Lines that find the queue full are dropped and counted (:attr:`DeferredLogger.dropped`,
in the node's summary): what the node does never waits on who reads its log. (A pipe that polls
writable has a free page, so a line shorter than :data:`MAX_LINE` is written without blocking.)
"""

from __future__ import annotations

import os
import queue
import select
import threading

# lines the queue holds: the node's warnings are throttled per kind (``log_throttle``), so a
# healthy sink never holds more than a few
CAPACITY = 256
_STOP = object()
# characters of one line at most: below a pipe's page (4096 bytes) even at 3 bytes a character
# (UTF-8 Δ, →), so that a write into a pipe that polls writable never blocks (rcutils adds ≈ 60
# bytes of severity, time and name); the node's messages quote bounded excerpts and stay far below
MAX_LINE = 1200


def console_fd() -> int:
    """The descriptor rcutils' console handler writes to (stderr unless
    ``RCUTILS_LOGGING_USE_STDOUT=1``)."""
    return 1 if os.environ.get("RCUTILS_LOGGING_USE_STDOUT") == "1" else 2


class DeferredLogger:
    """The ``debug``/``info``/``warning``/``error`` of an rclpy logger, written by a thread of its own.

    Parameters
    ----------
    logger : an ``rclpy`` ``RcutilsLogger`` (anything with those four methods)
    capacity : lines queued at most; beyond, lines are dropped and counted
    fd : the descriptor the logger writes to (default: :func:`console_fd`), polled before each line
    """

    def __init__(self, logger, capacity: int = CAPACITY, fd: int | None = None):
        self._logger = logger
        self._queue: queue.Queue = queue.Queue(maxsize=capacity)
        self._poll = select.poll()
        self._poll.register(console_fd() if fd is None else fd, select.POLLOUT)
        self._closing = threading.Event()
        self._stopped_cleanly = False         # the thread reached the end of the queue
        self.dropped = 0
        self._thread = threading.Thread(target=self._write, name="flexmb-log", daemon=True)
        self._thread.start()

    def _put(self, level: str, text: str) -> None:
        try:
            self._queue.put_nowait((level, text if len(text) <= MAX_LINE else text[:MAX_LINE] + "…"))
        except queue.Full:
            self.dropped += 1

    def debug(self, text: str) -> None:
        self._put("debug", text)

    def info(self, text: str) -> None:
        self._put("info", text)

    def warning(self, text: str) -> None:
        self._put("warning", text)

    def error(self, text: str) -> None:
        self._put("error", text)

    def _write(self) -> None:
        log = self._logger
        while True:
            item = self._queue.get()
            if item is _STOP:
                self._stopped_cleanly = True
                return
            level, text = item
            if not self._writable():          # closing, the sink still blocked: the rest is lost
                self.dropped += 1 + self._discard()
                return
            try:
                # one call site per level: rclpy refuses a call site whose severity changes
                # ("Logger severity cannot be changed between calls")
                if level == "warning":
                    log.warning(text)
                elif level == "info":
                    log.info(text)
                elif level == "error":
                    log.error(text)
                else:
                    log.debug(text)
            except Exception:         # a closed context at shutdown: the line is lost, not the thread
                self.dropped += 1

    def _discard(self) -> int:
        """Empty the queue; returns how many lines it held."""
        n = 0
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return n
            n += item is not _STOP

    def _writable(self) -> bool:
        """Wait (GIL released) until the sink takes a line without blocking; False if closing
        first. A descriptor that is closed or not pollable counts as writable (rcutils copes)."""
        while True:
            events = self._poll.poll(100)        # ms: a closing logger stops waiting within this
            if events:
                return True
            if self._closing.is_set():
                return False

    def close(self, timeout: float = 1.0) -> bool:
        """Write what is queued, waiting at most ``timeout`` s for a sink that blocks; True when
        all was written (else the rest is counted as dropped)."""
        try:
            self._queue.put(_STOP, timeout=timeout)
        except queue.Full:
            pass
        self._thread.join(timeout)
        if self._thread.is_alive():
            self._closing.set()
            self._thread.join(0.5)
        return self._stopped_cleanly
