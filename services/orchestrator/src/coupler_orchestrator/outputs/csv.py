"""results.csv: a header ``time,Component.connector,...`` then one row per recorded communication
point.

Reals are written with ``repr`` (the shortest text that reads back to the same double),
Booleans as 1/0, strings as they are (CSV-quoted), binary values as JSON text when their channel
names a registered protobuf message (``coupler.messages``), else as hex. Camera frames
(``coupler.v1.Image``) are never text: left out unless ``--output-variables`` picks them, then
PNG files whose names the cells hold (``outputs.frames``). Rows are buffered and
flushed at least once a second and on every exit path, so a crash loses at most the last second
and an interrupted or failed run keeps every completed row.

A row's line is made in one pass in C by the native CSV row (``coupler_native._rows``:
``packages/coupler-native/csrc/rows.c``): the Real, Integer, Boolean and String cells there,
the other columns' cells by their Python formatters; the same text as its Python twin
``RowTemplate`` (``row_formatter``'s %-format) makes where coupler-native is not installed:
the same ``native.RowLines``, the same bytes (``tests/test_twins.py``, ``test_csv_rows.py``).
The rows of several base steps the native FMU step took in one call are written from its row
log in one call into C too (``RowFormat.lines``), the same lines.
"""

from __future__ import annotations

import contextlib
import fnmatch
import os
import time as wallclock
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from coupler import messages
from coupler.channels import Value
from coupler_orchestrator.native import RowLines
from coupler_orchestrator.native import rows as native_rows
from coupler_orchestrator.observer import Column, Observer, RunEnd, RunInfo, Steps
from coupler_orchestrator.outputs.files import ResultsError
from coupler_orchestrator.outputs.frames import FrameStore, is_frame

FLUSH_EVERY_S = 1.0
"""Longest time a written row may stay in the buffer [s]."""

IN_C = "in C (the native CSV row)"


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


KINDS = {
    "Real": "r",
    "Integer": "i",
    "Enumeration": "i",
    "UInt64": "i",
    "Boolean": "b",
    "String": "s",
}
"""Column types whose cells the native CSV row makes itself (csrc/rows.c), by its kind codes
(a String cell that is not a str goes to its ``formatter``); it hands every other column's
value to that column's ``formatter``."""


def native_row_format(columns: Sequence[Column], picked: Sequence[int]) -> Any:
    """The native CSV row (``coupler_native._rows.RowFormat``) of the ``picked`` columns:
    ``line(time, row)`` makes ``row_formatter``'s lines in one pass in C, ``lines(log, first,
    every)`` those of a native FMU step's row log; None without coupler-native."""
    native = native_rows()
    if native is None:
        return None
    kinds = "".join(KINDS.get(columns[i].type, "o") for i in picked)
    cells = tuple(
        formatter(columns[i]) if k in "so" else None for k, i in zip(kinds, picked, strict=True)
    )
    return native.RowFormat(list(picked), kinds, cells)


def native_row_formatter(
    columns: Sequence[Column], picked: Sequence[int]
) -> Callable[[float, Sequence[Value]], str] | None:
    """``row_formatter``'s lines made in one pass in C; None without coupler-native."""
    made = native_row_format(columns, picked)
    if made is None:
        return None
    line: Callable[[float, Sequence[Value]], str] = made.line
    return line


def row_formatter(columns: Sequence[Column], picked: Sequence[int]) -> Callable[..., str]:
    """``(time, row) -> line``: the CSV line of the ``picked`` columns of a row, exactly the
    cells ``formatter`` makes, through one %-format made once (the columns of PLAIN types go
    in as they are, the others through their formatter first). Python's way, where
    coupler-native is not installed (``native_row_formatter`` makes the same lines)."""
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


class RowTemplate:
    """``RowLines`` in Python: ``row_formatter``'s lines (the twin of
    ``coupler_native._rows.RowFormat``)."""

    def __init__(self, columns: Sequence[Column], picked: Sequence[int]) -> None:
        self._line = row_formatter(columns, picked)

    def line(self, time: float, row: Sequence[Value], /) -> str:
        return self._line(time, row)


def csv_field(text: str) -> str:
    """``text`` as a field of a CSV row, quoted when it holds a comma, a quote or a newline:
    exactly what the csv module writes with lineterminator "\\n" (a lone carriage return is
    left as is, as the csv module does)."""
    if "," in text or '"' in text or "\n" in text:
        return '"' + text.replace('"', '""') + '"'
    return text


@dataclass(frozen=True, kw_only=True)
class Selection:
    """Which columns and which communication points results.csv records."""

    patterns: tuple[str, ...] = ()
    """Column names or globs (``Gain.*``, ``*.speed``); empty: every column but camera
    frames (``outputs.frames.is_frame``), which are recorded only when picked."""
    every: int = 1
    """Record every ``every``-th communication point (t_0 always)."""

    def columns(self, columns: Sequence[Column]) -> list[int]:
        """Indices of the selected columns, in column order."""
        if not self.patterns:
            return [i for i, c in enumerate(columns) if not is_frame(c)]
        return [
            i
            for i, c in enumerate(columns)
            if any(fnmatch.fnmatchcase(c.name, p) for p in self.patterns)
        ]


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
        self.rows = IN_C if native_rows() is not None else f"in Python: {native_rows.problem}"
        """How its lines are made (summary.json's ``results_rows``, ``coupler run -v``)."""
        self._file: IO[str] | None = None
        self._line: Callable[[float, Sequence[Value]], str] = row_formatter([], [])
        self._lines: Callable[[Any, int, int], str | None] | None = None
        """The lines of a native row log (``RowFormat.lines``), when made in C."""
        self._count = 0
        self._flushed = 0.0
        self._good = 0
        """Bytes of results.csv known to hold only complete rows (flushed without error)."""
        self._store = FrameStore(path.parent)
        self._frames: list[tuple[int, str]] = []
        """(index in a row, column name) of the picked frame columns."""

    def started(self, info: RunInfo) -> None:
        picked = self.selection.columns(info.columns)
        columns = [info.columns[i] for i in picked]
        self._frames = [(i, info.columns[i].name) for i in picked if is_frame(info.columns[i])]
        native = native_row_format(info.columns, picked)
        made: RowLines = native if native is not None else RowTemplate(info.columns, picked)
        self._line = made.line
        self._lines = native.lines if native is not None and not self._frames else None
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
            if self._frames:
                row = list(row)
                for i, name in self._frames:
                    row[i] = self._store.write(name, count, row[i])
            self._file.write(self._line(time, row))
            self._flush_due()
        except OSError as exc:
            self._fail(exc)

    def stepped_batch(self, steps: Steps) -> None:
        """The rows of several steps: their lines made from the native FMU step's row log in
        one call into C, one write; else row by row."""
        if self._file is None:
            self._count += len(steps.times)
            return
        lines = None
        if self._lines is not None and steps.log is not None:
            every = self.selection.every
            lines = self._lines(steps.log, -self._count % every, every)
        if lines is None:  # a column the log cannot give in C
            self._lines = None
            super().stepped_batch(steps)
            return
        self._count += len(steps.times)
        try:
            self._file.write(lines)
            self._flush_due()
        except OSError as exc:
            self._fail(exc)

    def _flush_due(self) -> None:
        """Flush once FLUSH_EVERY_S has passed since the last flush."""
        assert self._file is not None
        now = wallclock.monotonic()
        if now - self._flushed >= FLUSH_EVERY_S:
            self._file.flush()
            self._good = self._file.tell()
            self._flushed = now

    def closing(self, end: RunEnd) -> None:
        file = self._file
        if file is None:
            return
        try:
            file.flush()
            os.fsync(file.fileno())  # a full disk may say so only here
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
        raise ResultsError(
            f"cannot write {self.path}: {exc.strerror or exc}; it keeps {rows_kept(self.path)}"
        ) from exc


def rows_kept(results: Path) -> str:
    """Which rows results.csv holds, for people: ``the rows up to t=5.3 s (54 rows)``,
    ``its header only`` or ``no row``."""
    try:
        with results.open("rb") as file:
            rows = sum(chunk.count(b"\n") for chunk in iter(lambda: file.read(1 << 20), b"")) - 1
            size = file.seek(0, os.SEEK_END)
            file.seek(max(0, size - 65536))
            lines = file.read().splitlines()
    except OSError:
        return "no row"
    last = lines[-1].split(b",", 1)[0] if lines else b""
    try:
        return f"the rows up to t={float(last):g} s ({rows} rows)"
    except ValueError:
        return "its header only" if lines else "no row"
