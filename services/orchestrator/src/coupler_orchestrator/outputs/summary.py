"""summary.json: it exists from the start of a run (status ``running``), is refreshed every few
seconds while it runs and rewritten when it ends, always atomically (never half-written): status,
reason, steps, wall time, real-time factor, each member's step latency (what the master saw)
and step cost (what the member's step cost it, by its own account), the recorded columns,
and at the end of a completed (or terminated) run the reports installed packages make from its
results (``outputs.reports``)."""

from __future__ import annotations

import time as wallclock
from collections.abc import Mapping, Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any

from coupler.channels import Value
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo, Steps
from coupler_orchestrator.outputs.files import write_json
from coupler_orchestrator.outputs.latency import LatencyStats
from coupler_orchestrator.outputs.reports import make_reports

SUMMARY_EVERY_S = 5.0
"""How often summary.json is refreshed while a run goes [s]."""


class SummaryWriter(Observer):
    """Writes summary.json: at the start (``running``), every few seconds, and at the end."""

    BATCH = 256
    """Steps whose latencies are kept before they are counted (counting in batches costs a
    third of counting step by step); every summary counts all of them."""

    def __init__(self, path: Path, *, extra: Mapping[str, Any]) -> None:
        self.path = path
        self.extra = dict(extra)
        self.summary: dict[str, Any] = {}
        self._info: RunInfo | None = None
        self._latency: list[LatencyStats] = []
        self._cost: list[LatencyStats] = []
        self._waited: list[LatencyStats] = []
        self._timings: list[Sequence[float | None]] = []
        """Each step's latencies (one per member) not yet folded into ``_latency``."""
        self._costs: list[Sequence[float | None]] = []
        self._waits: list[Sequence[float | None]] = []
        """Each step's costs and waits (one per member) not yet folded into their stats."""
        self._time = 0.0
        self._points = 0
        self._wall_start = wallclock.monotonic()
        self._written = 0.0

    def started(self, info: RunInfo) -> None:
        self._info = info
        self._latency = [LatencyStats() for _ in info.members]
        self._cost = [LatencyStats() for _ in info.members]
        self._waited = [LatencyStats() for _ in info.members]
        self._time = info.start_time
        self._wall_start = wallclock.monotonic()
        self._write(None)

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        self._time = time
        self._points += 1
        if wallclock.monotonic() - self._written >= SUMMARY_EVERY_S:
            self._write(None)

    def timed(self, seconds: Sequence[float | None]) -> None:
        self._timings.append(seconds)
        if len(self._timings) >= self.BATCH:
            self._fold()

    def costed(self, seconds: Sequence[float | None], waited: Sequence[float | None]) -> None:
        self._costs.append(seconds)
        self._waits.append(waited)

    def stepped_batch(self, steps: Steps) -> None:
        """Several steps: each member's latencies counted in one batch."""
        self._time = steps.times[-1]
        self._points += len(steps.times)
        for i, (stats, cost) in enumerate(zip(self._latency, self._cost, strict=True)):
            samples = steps.samples(i)
            stats.add_all(samples)
            cost.add_all(samples)  # computed here: a step's cost is its latency
        if wallclock.monotonic() - self._written >= SUMMARY_EVERY_S:
            self._write(None)

    def finished(self, end: RunEnd) -> None:
        """The final summary; the reports first when the run got to its end (results.csv is
        complete: its recorder is told before this one)."""
        if end.status in ("completed", "terminated") and self._info is not None:
            reports = make_reports(self.path.parent, self._info.columns)
            if reports:
                self.extra["reports"] = reports
        self._write(end)

    def _fold(self) -> None:
        """The kept steps' latencies, costs and waits into each member's statistics, member by
        member."""
        for kept, statistics in (
            (self._timings, self._latency),
            (self._costs, self._cost),
            (self._waits, self._waited),
        ):
            for i, stats in enumerate(statistics):
                stats.add_all([s for row in kept if (s := row[i]) is not None])
            kept.clear()

    def _write(self, end: RunEnd | None) -> None:
        info = self._info
        if info is None:
            return
        self._fold()
        wall = end.wall_time if end else wallclock.monotonic() - self._wall_start
        simulated = (end.end_time if end else self._time) - info.start_time
        self.summary = {
            "status": end.status if end else "running",
            "reason": end.reason if end else "",
            "run_id": info.run_id,
            "algorithm": info.algorithm,
            "start_time": info.start_time,
            "stop_time": info.stop_time,
            "end_time": end.end_time if end else self._time,
            "step_size": info.step_size,
            "steps": end.steps if end else max(self._points - 1, 0),
            "steps_planned": info.steps,
            "wall_time_s": round(wall, 6),
            "realtime_factor": round(simulated / wall, 3) if wall > 0 else None,
            "participants": {
                name: {
                    "multiple": multiple,
                    "steps": stats.count,
                    "do_step_latency_ms": stats.summary_ms(),
                    "step_cost_ms": cost.summary_ms(),
                    "waited_ms": waited.summary_ms(),
                }
                for name, multiple, stats, cost, waited in zip(
                    info.members,
                    info.multiples,
                    self._latency,
                    self._cost,
                    self._waited,
                    strict=True,
                )
            },
            "columns": [
                {"name": c.name, "unit": c.unit, "type": c.type}
                | ({"message_type": c.message_type} if c.message_type else {})
                for c in info.columns
            ],
            **self.extra,
        }
        if end is not None:
            for name, stepped in end.step_paths.items():
                self.summary["participants"][name]["step_path"] = {
                    "path": stepped.path,
                    "reason": stepped.reason,
                }
        self._written = wallclock.monotonic()
        write_json(self.path, self.summary)


def coupler_version() -> str:
    return version("coupler-orchestrator")
