"""A progress bar over completed runs, written to a stream the caller owns (the CLI: stderr).

On a terminal it redraws one line; elsewhere (logs, CI) it writes a line at every 10 % step.
"""

from __future__ import annotations

import time
from typing import TextIO


class ProgressBar:
    """``bar(event)`` after each run (an :class:`~flexmb_core.study.sweep.SweepEvent`)."""

    def __init__(self, stream: TextIO, width: int = 30):
        self.stream = stream
        self.width = width
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.t0 = time.perf_counter()
        self.last_decile = -1

    def __call__(self, ev) -> None:
        frac = ev.done / ev.total if ev.total else 1.0
        line = (f"[{'#' * int(self.width * frac):{self.width}s}] {ev.done}/{ev.total} runs "
                f"({ev.computed} computed, {ev.cached} stored, {ev.failed} failed) "
                f"{time.perf_counter() - self.t0:6.1f} s")
        if self.tty:
            self.stream.write("\r" + line + ("\n" if ev.done == ev.total else ""))
        else:
            decile = int(10 * frac)
            if decile == self.last_decile and ev.done != ev.total:
                return
            self.last_decile = decile
            self.stream.write(line + "\n")
        self.stream.flush()
