"""Results of a run: ``results.csv`` (flushed row by row) and ``summary.json``.

results.csv: a header ``time,Component.connector,...`` then one row per communication point.
Reals are written with ``repr`` (shortest text that reads back to the same double), Booleans as
1/0, strings as they are (CSV-quoted), binary values as hex. Units are in summary.json
(``columns``), so the CSV stays plain numbers any tool reads.
"""

from __future__ import annotations

import csv
import hashlib
import json
from collections.abc import Mapping, Sequence
from importlib.metadata import version
from pathlib import Path
from typing import IO, Any

from coupler.channels import Value
from coupler_orchestrator.observer import Observer, RunInfo


def format_value(value: Value) -> str:
    """The CSV text of one value."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, bytes):
        return value.hex()
    return str(value)


class CsvRecorder(Observer):
    """Writes results.csv; every row is flushed as written, so an aborted run keeps its steps."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: IO[str] | None = None
        self._writer: Any = None

    def started(self, info: RunInfo) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("w", encoding="utf-8", newline="")
        self._writer = csv.writer(self._file, lineterminator="\n")
        self._writer.writerow(["time", *(c.name for c in info.columns)])
        self._file.flush()

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        assert self._file is not None
        self._writer.writerow([repr(time), *(format_value(v) for v in row)])
        self._file.flush()

    def finished(self, summary: Mapping[str, Any]) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


class SummaryWriter(Observer):
    """Writes summary.json when the run ends, with what the run itself cannot know."""

    def __init__(self, path: Path, *, extra: Mapping[str, Any]) -> None:
        self.path = path
        self.extra = dict(extra)
        self.summary: dict[str, Any] = {}

    def finished(self, summary: Mapping[str, Any]) -> None:
        self.summary = {**summary, **self.extra}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.write_text(json.dumps(self.summary, indent=2, sort_keys=False) + "\n")


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as file:
        for chunk in iter(lambda: file.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def coupler_version() -> str:
    return version("coupler-orchestrator")
