"""Stage 8: what a run leaves behind — ``results.csv``, ``summary.json`` and latency statistics.

results.csv: a header ``time,Component.connector,...`` then one row per recorded communication
point. Reals are written with ``repr`` (the shortest text that reads back to the same double),
Booleans as 1/0, strings as they are (CSV-quoted), binary values as JSON text when their channel
names a registered protobuf message (``coupler.messages``), else as hex. Rows are buffered and
flushed at least once a second and on every exit path, so a crash loses at most the last second
and an interrupted or failed run keeps every completed row.

summary.json exists from the start of a run (status ``running``), is refreshed every few
seconds while it runs and rewritten when it ends, always atomically (never half-written).
Latency statistics are kept in constant memory (a log-bucketed histogram): a run of a million
steps costs what a run of ten does.
"""

from __future__ import annotations

import contextlib
import fnmatch
import io
import json
import math
import os
import time as wallclock
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path
from typing import IO, Any

from coupler import messages
from coupler.channels import Value
from coupler.errors import CouplerError, ScenarioError
from coupler_orchestrator.observer import Column, Observer, RunEnd, RunInfo

FLUSH_EVERY_S = 1.0
"""Longest time a written row may stay in the buffer [s]."""
SUMMARY_EVERY_S = 5.0
"""How often summary.json is refreshed while a run goes [s]."""


class ResultsError(CouplerError):
    """Results cannot be written (a full disk, a directory that went away)."""


def format_value(value: Value, column: Column | None = None) -> str:
    """The CSV text of one value of ``column``."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, bytes):
        if column is not None and column.message_type and messages.known(column.message_type):
            return messages.message_json(column.message_type, value) if value else ""
        return value.hex()
    return str(value)


def formatter(column: Column) -> Callable[[Value], str]:
    """``format_value`` for one column as a CSV field (quoted as the csv module quotes it),
    chosen once: the CSV writer calls it for every cell."""
    if column.type == "Real":
        return repr
    if column.type == "Boolean":
        return lambda value: "1" if value else "0"
    if column.type in ("Integer", "Enumeration", "UInt64"):
        return str
    return lambda value: csv_field(format_value(value, column))


PLAIN = {"Real": "%r", "Integer": "%s", "Enumeration": "%s", "UInt64": "%s"}
"""Column types whose cell is the value's repr or str (what ``formatter`` chooses for them),
written by a %-format."""


def row_formatter(columns: Sequence[Column], picked: Sequence[int]) -> Callable[..., str]:
    """``(time, row) -> line``: the CSV line of the ``picked`` columns of a row, exactly the
    cells ``formatter`` makes, through one %-format made once (the columns of PLAIN types go
    in as they are, the others through their formatter first)."""
    template = ",".join(["%r", *(PLAIN.get(columns[i].type, "%s") for i in picked)]) + "\n"
    special = [
        (j, formatter(columns[i])) for j, i in enumerate(picked) if columns[i].type not in PLAIN
    ]
    indices = list(picked)

    def line(time: float, row: Sequence[Value]) -> str:
        cells: list[Any] = [time]
        cells += [row[i] for i in indices]
        for j, format_cell in special:
            cells[j + 1] = format_cell(cells[j + 1])
        return template % tuple(cells)

    return line


def csv_field(text: str) -> str:
    """``text`` as a field of a CSV row, quoted when it holds a comma, a quote or a newline:
    exactly what the csv module writes with lineterminator "\\n" (a lone carriage return is
    left as is, as the csv module does)."""
    if "," in text or '"' in text or "\n" in text:
        return '"' + text.replace('"', '""') + '"'
    return text


def check_writable(directory: Path) -> None:
    """ScenarioError unless results can be written into ``directory`` (created if missing) —
    checked before any participant starts."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".coupler-write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ScenarioError(
            f"cannot write results into {directory}: {exc.strerror or exc}; choose another "
            "--out directory"
        ) from exc


@dataclass(frozen=True, kw_only=True)
class Selection:
    """Which columns and which communication points results.csv records."""

    patterns: tuple[str, ...] = ()
    """Column names or globs (``Gain.*``, ``*.speed``); empty: every column."""
    every: int = 1
    """Record every ``every``-th communication point (t_0 always)."""

    def columns(self, columns: Sequence[Column]) -> list[int]:
        """Indices of the selected columns, in column order."""
        if not self.patterns:
            return list(range(len(columns)))
        return [
            i
            for i, c in enumerate(columns)
            if any(fnmatch.fnmatchcase(c.name, p) for p in self.patterns)
        ]


def _write_failed(path: Path, exc: OSError) -> ResultsError:
    return ResultsError(
        f"cannot write {path}: {exc.strerror or exc}; every complete row before it is kept"
    )


def _cut(path: Path, good: int) -> None:
    """Cut a file after its last complete line at or after byte ``good`` (best effort): every
    row that reached the disk whole stays, no half-written row survives."""
    with contextlib.suppress(OSError), path.open("rb") as file:
        file.seek(good)
        tail = file.read()
        os.truncate(path, good + tail.rfind(b"\n") + 1)


class CsvRecorder(Observer):
    """Writes results.csv: buffered, flushed once a second and when the run ends."""

    def __init__(self, path: Path, selection: Selection | None = None) -> None:
        self.path = path
        self.selection = selection or Selection()
        self._file: IO[str] | None = None
        self._line: Callable[[float, Sequence[Value]], str] = row_formatter([], [])
        self._count = 0
        self._flushed = 0.0
        self._good = 0
        """Bytes of results.csv known to hold only complete rows (flushed without error)."""

    def started(self, info: RunInfo) -> None:
        picked = self.selection.columns(info.columns)
        columns = [info.columns[i] for i in picked]
        self._line = row_formatter(info.columns, picked)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = self.path.open("w", encoding="utf-8", newline="", buffering=1 << 16)
            header = ["time", *(csv_field(c.name) for c in columns)]
            self._file.write(",".join(header) + "\n")
            self._file.flush()
            self._good = self._file.tell()
        except OSError as exc:
            self._fail(exc)
        self._flushed = wallclock.monotonic()

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        count, self._count = self._count, self._count + 1
        if count % self.selection.every or self._file is None:
            return
        try:
            self._file.write(self._line(time, row))
            now = wallclock.monotonic()
            if now - self._flushed >= FLUSH_EVERY_S:
                self._file.flush()
                self._good = self._file.tell()
                self._flushed = now
        except OSError as exc:
            self._fail(exc)

    def finished(self, end: RunEnd) -> None:
        file = self._file
        if file is None:
            return
        try:
            file.flush()
        except OSError as exc:
            self._fail(exc)
        self._file = None
        file.close()

    def _fail(self, exc: OSError) -> None:
        """Drop what could not be written whole, keep every complete row, say why."""
        file, self._file = self._file, None
        if file is not None:
            with contextlib.suppress(OSError):
                file.close()  # may fail again flushing the rest; the cut below removes it
        _cut(self.path, self._good)
        raise _write_failed(self.path, exc) from exc


class ParquetRecorder(Observer):
    """Writes results.parquet (when pyarrow is installed): the rows results.csv holds, typed —
    Real float64, Integer/Enumeration int64, Boolean bool, String string, Binary binary (or
    the JSON text of a registered message) — in row groups of ``group_rows`` rows, so memory
    stays bounded; the last group is written on every exit path."""

    def __init__(self, path: Path, selection: Selection | None = None, group_rows: int = 65536):
        import pyarrow  # checked by parquet_available() before a run

        self._pa = pyarrow
        self.path = path
        self.selection = selection or Selection()
        self.group_rows = group_rows
        self._writer: Any = None
        self._schema: Any = None
        self._columns: list[Column] = []
        self._picked: list[int] = []
        self._buffer: list[list[Any]] = []
        self._count = 0

    def started(self, info: RunInfo) -> None:
        import pyarrow.parquet

        pa = self._pa
        self._picked = self.selection.columns(info.columns)
        self._columns = [info.columns[i] for i in self._picked]
        kinds = {
            "Real": pa.float64(),
            "Integer": pa.int64(),
            "Enumeration": pa.int64(),
            "Boolean": pa.bool_(),
            "String": pa.string(),
        }
        fields = [pa.field("time", pa.float64())]
        for column in self._columns:
            kind = kinds.get(column.type)
            if kind is None:  # Binary: JSON text of a registered message, else bytes
                known = column.message_type and messages.known(column.message_type)
                kind = pa.string() if known else pa.binary()
            fields.append(pa.field(column.name, kind))
        self._schema = pa.schema(fields)
        self._buffer = [[] for _ in fields]
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = pyarrow.parquet.ParquetWriter(str(self.path), self._schema)
        except OSError as exc:
            raise _write_failed(self.path, exc) from exc

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        count, self._count = self._count, self._count + 1
        if count % self.selection.every or self._writer is None:
            return
        self._buffer[0].append(time)
        for cells, column, i in zip(self._buffer[1:], self._columns, self._picked, strict=True):
            value = row[i]
            if (
                isinstance(value, bytes)
                and self._schema.field(column.name).type == self._pa.string()
            ):
                value = format_value(value, column)
            cells.append(value)
        if len(self._buffer[0]) >= self.group_rows:
            self._flush()

    def _flush(self) -> None:
        if not self._buffer or not self._buffer[0]:
            return
        table = self._pa.Table.from_arrays(
            [
                self._pa.array(cells, type=f.type)
                for cells, f in zip(self._buffer, self._schema, strict=True)
            ],
            schema=self._schema,
        )
        try:
            self._writer.write_table(table)
        except OSError as exc:
            raise _write_failed(self.path, exc) from exc
        self._buffer = [[] for _ in self._buffer]

    def finished(self, end: RunEnd) -> None:
        writer = self._writer
        if writer is None:
            return
        try:
            self._flush()
        finally:
            self._writer = None
            writer.close()


def parquet_available() -> bool:
    """Whether results.parquet can be written (the pyarrow package is installed)."""
    import importlib.util

    return importlib.util.find_spec("pyarrow") is not None


class LatencyStats:
    """Step latencies in constant memory: count, sum, max, and a histogram of log buckets 1 %
    wide from 100 ns up, which gives any percentile within 1 %."""

    _BASE = 1e-7
    _WIDTH = math.log1p(0.01)

    def __init__(self) -> None:
        self.count = 0
        self.total = 0.0
        self.maximum = 0.0
        self._buckets: dict[int, int] = {}

    def add_all(self, samples: Sequence[float]) -> None:
        """Count a batch of samples (one call per batch: the step loop's samples are folded in
        every ``SummaryWriter.BATCH`` steps)."""
        if not samples:
            return
        self.count += len(samples)
        self.total += sum(samples)
        self.maximum = max(self.maximum, *samples)
        buckets, log, base = self._buckets, math.log, self._BASE
        floor, per_bucket = log(base), 1 / self._WIDTH
        for seconds in samples:
            bucket = int((log(seconds) - floor) * per_bucket) if seconds > base else 0
            buckets[bucket] = buckets.get(bucket, 0) + 1

    def percentile(self, q: float) -> float:
        """The ``q`` quantile (0..1) [s], within 1 %."""
        rank = q * (self.count - 1)
        seen = 0
        for bucket in sorted(self._buckets):
            seen += self._buckets[bucket]
            if seen > rank:
                return min(self._BASE * math.exp((bucket + 0.5) * self._WIDTH), self.maximum)
        return self.maximum

    def summary_ms(self) -> dict[str, float] | None:
        if not self.count:
            return None
        return {
            "mean": round(self.total / self.count * 1e3, 4),
            "p50": round(self.percentile(0.5) * 1e3, 4),
            "p99": round(self.percentile(0.99) * 1e3, 4),
            "max": round(self.maximum * 1e3, 4),
        }


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
        self._timings: list[Sequence[float | None]] = []
        """Each step's latencies (one per member) not yet folded into ``_latency``."""
        self._time = 0.0
        self._points = 0
        self._wall_start = wallclock.monotonic()
        self._written = 0.0

    def started(self, info: RunInfo) -> None:
        self._info = info
        self._latency = [LatencyStats() for _ in info.members]
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

    def finished(self, end: RunEnd) -> None:
        self._write(end)

    def _fold(self) -> None:
        """The kept steps' latencies into each member's statistics, member by member."""
        timings, self._timings = self._timings, []
        for i, stats in enumerate(self._latency):
            stats.add_all([s for row in timings if (s := row[i]) is not None])

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
                }
                for name, multiple, stats in zip(
                    info.members, info.multiples, self._latency, strict=True
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


def write_json(path: Path, data: Mapping[str, Any]) -> None:
    """Write ``data`` to ``path`` atomically (a reader never sees half a file)."""
    text = io.StringIO()
    json.dump(data, text, indent=2)
    text.write("\n")
    partial = path.with_name(f".{path.name}.partial")
    encoded = text.getvalue().encode()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial.write_bytes(encoded)
        os.replace(partial, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            partial.unlink()
        try:  # a full disk: rewrite in place, in the blocks the file already has
            with path.open("r+b") as file:
                file.write(encoded)
                file.truncate()
        except OSError:
            raise ResultsError(f"cannot write {path}: {exc.strerror or exc}") from exc


def coupler_version() -> str:
    return version("coupler-orchestrator")
