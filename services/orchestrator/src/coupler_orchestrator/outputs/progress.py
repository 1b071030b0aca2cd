"""Progress of a run on stderr: a bar on a terminal, plain lines in logs (CI, compose).

Both show the simulated time reached, the share of the run, the real-time factor and an ETA;
neither ever slows the run (they draw at most ten times a second, respectively every
``every`` seconds).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import IO

from coupler.channels import Value
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo, Steps


class _Progress(Observer):
    """What the bar and the lines share: where the run is and how fast it goes."""

    def __init__(self, stream: IO[str] | None) -> None:
        self._stream = stream
        self._info: RunInfo | None = None
        self._started = 0.0

    @property
    def stream(self) -> IO[str]:
        return self._stream or sys.stderr  # the current stderr (test runners swap it)

    def started(self, info: RunInfo) -> None:
        self._info = info
        self._started = time.monotonic()

    def stepped_batch(self, steps: Steps) -> None:
        """Several steps: where the last one got to is all either shows."""
        self.stepped(steps.times[-1], ())

    def status(self, time_s: float, now: float) -> tuple[float, str]:
        """(fraction done, 't=.../... s  NN.N%  RTFx real time  ETA ...')."""
        assert self._info is not None
        info = self._info
        span = info.stop_time - info.start_time
        done = (time_s - info.start_time) / span if span > 0 else 1.0
        elapsed = now - self._started
        simulated = time_s - info.start_time
        rtf = simulated / elapsed if elapsed > 0 else 0.0
        eta = (info.stop_time - time_s) / rtf if rtf > 0 else float("inf")
        return done, (
            f"t={time_s:.6g}/{info.stop_time:.6g} s  {done:6.1%}  {rtf:.3g}x real time  "
            f"ETA {duration(eta)}"
        )


def duration(seconds: float) -> str:
    if seconds == float("inf"):
        return "?"
    seconds = round(seconds)
    if seconds < 60:
        return f"{seconds} s"
    minutes, seconds = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes} min {seconds:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


class ProgressBar(_Progress):
    """A bar redrawn in place on a terminal; silent for the first ``delay`` seconds."""

    def __init__(
        self, stream: IO[str] | None = None, *, delay: float = 2.0, width: int = 30
    ) -> None:
        super().__init__(stream)
        self.delay = delay
        self.width = width
        self._drawn = 0.0
        self._shown = False

    def stepped(self, time_s: float, row: Sequence[Value]) -> None:
        now = time.monotonic()
        if self._info is None or now - self._started < self.delay or now - self._drawn < 0.1:
            return
        self._drawn = now
        self._draw(time_s, now)

    def _draw(self, time_s: float, now: float) -> None:
        done, text = self.status(time_s, now)
        filled = round(min(max(done, 0.0), 1.0) * self.width)
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {text} ")
        self.stream.flush()
        self._shown = True

    def finished(self, end: RunEnd) -> None:
        if self._shown:
            self._draw(end.end_time, time.monotonic())
            self.stream.write("\n")
            self.stream.flush()


class ProgressLines(_Progress):
    """One plain line every ``every`` seconds (for logs, where a bar would be garbage)."""

    def __init__(self, stream: IO[str] | None = None, *, every: float = 10.0) -> None:
        super().__init__(stream)
        self.every = every
        self._next = 0.0

    def started(self, info: RunInfo) -> None:
        super().started(info)
        self._next = self._started + self.every

    def stepped(self, time_s: float, row: Sequence[Value]) -> None:
        now = time.monotonic()
        if self._info is None or now < self._next:
            return
        self._next = now + self.every
        self.stream.write(f"progress: {self.status(time_s, now)[1]}\n")
        self.stream.flush()
