"""What the terminal shows while a campaign runs: runs done, failed and running, and an ETA."""

from __future__ import annotations

import time
from typing import IO

from coupler_orchestrator.outputs.progress import duration
from coupler_orchestrator.tools.campaign.model import COMPLETED, RunJob, RunReport


class CampaignProgress:
    """Runs done/failed/running and an ETA: redrawn in place on a terminal, a line per ended run
    otherwise."""

    def __init__(self, stream: IO[str] | None, *, tty: bool | None = None) -> None:
        self._stream = stream
        self.tty = stream.isatty() if tty is None and stream is not None else bool(tty)
        self.total = self.done_count = self.failed = self.skipped = 0
        self._running = 0
        self._started = 0.0

    def begin(self, total: int, skipped: int) -> None:
        self.total, self.skipped, self.done_count = total, skipped, skipped
        self._started = time.monotonic()
        if skipped:
            self._write(
                f"campaign: {skipped} of {total} runs completed earlier (--force runs them again)\n"
            )

    def running(self, job: RunJob) -> None:
        self._running += 1
        if self.tty:
            self._draw()

    def done(self, report: RunReport) -> None:
        self._running -= 1
        self.done_count += 1
        if report.status not in COMPLETED:
            self.failed += 1
        if self.tty:
            self._draw()
        else:
            reason = (
                f": {report.reason}" if report.reason and report.status not in COMPLETED else ""
            )
            self._write(f"campaign: run {report.index} {report.status}{reason} ({self.line()})\n")

    def line(self) -> str:
        ran = self.done_count - self.skipped
        left = self.total - self.done_count
        elapsed = time.monotonic() - self._started
        eta = elapsed / ran * left if ran else float("inf")
        return (
            f"{self.done_count}/{self.total} done, {self.failed} failed, {self._running} running, "
            f"ETA {duration(eta) if left else '0 s'}"
        )

    def end(self) -> None:
        if self.tty:
            self._write("\n")

    def _draw(self) -> None:
        width = 30
        filled = round(width * self.done_count / self.total) if self.total else width
        self._write(f"\r[{'#' * filled}{'.' * (width - filled)}] runs {self.line()} ")

    def _write(self, text: str) -> None:
        stream = self._stream
        if stream is None:
            return
        stream.write(text)
        stream.flush()
