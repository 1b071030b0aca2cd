"""Reports made from a run's results when it ends, by the packages that know what they mean.

The orchestrator knows no domain: an installed package declares a report in the entry point
group ``coupler.reports`` (``pyproject.toml``)::

    [project.entry-points."coupler.reports"]
    perception = "coupler_railway.scoring:run_report"

and every run that completes (or is ended by a participant) calls each one with its results
folder (results.csv written whole) and its recorded columns (name -> protobuf message type, ``""``
for none). A report returns None when the run is not its business, else what summary.json holds
under ``reports.<name>`` (JSON values), writing any files of its own into the folder. A report
that fails is logged and noted there as ``{"error": ...}``: it never changes how the run ended.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

import structlog

from coupler_orchestrator.observer import Column

ENTRY_POINTS = "coupler.reports"
"""The entry point group installed packages name their reports in."""

Report = Callable[[Path, Mapping[str, str]], Mapping[str, Any] | None]
"""``report(results_folder, {column: message_type}) -> summary entry | None``."""

log = structlog.get_logger("coupler.reports")


def make_reports(folder: Path, columns: Sequence[Column]) -> dict[str, Any]:
    """Every installed report's entry for the run whose results are in ``folder``."""
    recorded = {c.name: c.message_type for c in columns}
    made: dict[str, Any] = {}
    for entry in entry_points(group=ENTRY_POINTS):
        try:
            report: Report = entry.load()
            result = report(folder, recorded)
        except Exception as exc:  # a report's failure is its own, never the run's
            log.warning("report_failed", report=entry.name, error=repr(exc))
            made[entry.name] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
        if result is not None:
            made[entry.name] = dict(result)
    return made
