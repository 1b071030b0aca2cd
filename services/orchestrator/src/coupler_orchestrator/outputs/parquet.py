"""results.parquet (``--parquet``, needs the pyarrow package): the rows results.csv holds, typed."""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from coupler import messages
from coupler.channels import Value
from coupler_orchestrator.observer import Column, Observer, RunEnd, RunInfo
from coupler_orchestrator.outputs.csv import Selection, format_value
from coupler_orchestrator.outputs.files import ResultsError
from coupler_orchestrator.outputs.frames import is_frame


class ParquetRecorder(Observer):
    """Writes results.parquet (when pyarrow is installed): the rows results.csv holds, typed —
    Real float64, Integer/Enumeration int64, Boolean bool, String string, Binary binary (or
    the JSON text of a registered message) — in row groups of ``group_rows`` rows, so memory
    stays bounded; the last group is written on every exit path. A file that could not be
    written whole (a full disk, a size limit) is removed at the run's end, never left behind
    unreadable: results.csv keeps the rows."""

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
        self._failed = False

    def started(self, info: RunInfo) -> None:
        import pyarrow.parquet

        pa = self._pa
        # frames are files: results.csv names them (outputs.frames)
        picked = self.selection.columns(info.columns)
        self._picked = [i for i in picked if not is_frame(info.columns[i])]
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
            with contextlib.suppress(OSError):
                self.path.unlink(missing_ok=True)
            raise self._write_failed(exc) from exc

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
        self._buffer = [[] for _ in self._buffer]
        try:
            self._writer.write_table(table)
        except OSError as exc:
            raise self._write_failed(exc) from exc

    def _write_failed(self, exc: OSError) -> ResultsError:
        self._failed = True
        return ResultsError(
            f"cannot write {self.path}: {exc.strerror or exc}; it is removed at the run's end "
            "(results.csv keeps every complete row)"
        )

    def closing(self, end: RunEnd) -> None:
        writer = self._writer
        if writer is None:
            return
        try:
            if not self._failed:
                self._flush()
                writer.close()
        except OSError as exc:
            raise self._write_failed(exc) from exc
        finally:
            self._writer = None
            if self._failed:
                with contextlib.suppress(Exception):
                    writer.close()
                self.path.unlink(missing_ok=True)


def parquet_available() -> bool:
    """Whether results.parquet can be written (the pyarrow package is installed)."""
    import importlib.util

    return importlib.util.find_spec("pyarrow") is not None
