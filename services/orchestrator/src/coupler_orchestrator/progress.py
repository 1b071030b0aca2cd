"""A progress bar on stderr for runs that last longer than two seconds on a terminal."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import IO

from coupler.channels import Value
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo


class ProgressBar(Observer):
    """Redraws at most ten times a second; silent for the first ``delay`` seconds."""

    def __init__(self, stream: IO[str] | None = None, *, delay: float = 2.0, width: int = 30):
        self.stream = stream or sys.stderr
        self.delay = delay
        self.width = width
        self._info: RunInfo | None = None
        self._started = 0.0
        self._drawn = 0.0
        self._shown = False

    def started(self, info: RunInfo) -> None:
        self._info = info
        self._started = time.monotonic()

    def stepped(self, time_s: float, row: Sequence[Value]) -> None:
        now = time.monotonic()
        if self._info is None or now - self._started < self.delay or now - self._drawn < 0.1:
            return
        self._drawn = now
        self._draw(time_s, now)

    def _draw(self, time_s: float, now: float) -> None:
        assert self._info is not None
        info = self._info
        span = info.stop_time - info.start_time
        done = (time_s - info.start_time) / span if span > 0 else 1.0
        filled = round(done * self.width)
        elapsed = now - self._started
        rtf = (time_s - info.start_time) / elapsed if elapsed > 0 else 0.0
        bar = "#" * filled + "." * (self.width - filled)
        self.stream.write(
            f"\r[{bar}] {done:6.1%}  t={time_s:.6g}/{info.stop_time:.6g} s  {rtf:.3g}x real time"
        )
        self.stream.flush()
        self._shown = True

    def finished(self, end: RunEnd) -> None:
        if self._shown:
            self._draw(end.end_time, time.monotonic())
            self.stream.write("\n")
            self.stream.flush()
