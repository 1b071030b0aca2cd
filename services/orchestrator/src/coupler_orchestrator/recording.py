"""Recordings of one participant's outputs (``coupler run --record``), and reading them back.

A recording holds, for one component, every output at every one of its communication points,
lossless and typed (Real as the float64 bits, Integer, Boolean, String, Binary with its message
type), the time grid of the run and the participant's declared channels. ``coupler.replay``
serves it again. docs/replay.md describes the file format (``.crec``), version 2::

    b"CREC"  u16 version  u32 N  u32 crc32(header)  N bytes of UTF-8 JSON header
    then blocks, each:  u32 L  u64 j0  u32 n  u32 crc32(payload)  u32 crc32(these 20 bytes)
        and L bytes of payload: n records, each  u32 R  R bytes:
            u64 j  f64 time  each output in header order:
                Real f64 | Integer, Enumeration i64 | Boolean u8 | String, Binary u32 n + n bytes
    then the seal, a block with L = 0, n = 0 and j0 = the number of points recorded.

little-endian throughout; when the component asked to end the run, a last record with
j = 2**64 - 1 holds the time and its reason (a String). Blocks (about ``BLOCK_BYTES``, or what
one second of the run recorded) are appended whole as the run goes: a run that is killed
leaves every complete block readable, and a block cut off at the end of a file without its seal
is the only damage read as the end of the recording; any other mismatch (a checksum, a count,
a gap) refuses the file, naming the block. Reading is streaming: ``read`` checks every block's
checksums and keeps one small entry per block; ``Points`` decodes one block at a time, so
memory is bounded by a block, never by the file. Version 1 files (no checksums) are refused,
naming the version.
"""

from __future__ import annotations

import bisect
import dataclasses
import json
import math
import os
import struct
import time as wallclock
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from coupler.channels import Capabilities, Causality, Channel, Description, Value, ValueType
from coupler.errors import CouplerError, ScenarioError
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo

MAGIC = b"CREC"
VERSION = 2
SUFFIX = ".crec"
_PREFIX = struct.Struct("<4sHII")
_LENGTH = struct.Struct("<I")
_BLOCK = struct.Struct("<IQII")
"""Payload length, first point's j, records, crc32 of the payload; then the crc32 of these."""
_BLOCK_HEAD = _BLOCK.size + _LENGTH.size
_POINT = struct.Struct("<Qd")
_REAL, _INT, _BOOL = struct.Struct("<d"), struct.Struct("<q"), struct.Struct("<B")
END = 2**64 - 1
"""j of the record saying the component asked to end the run there (after the last point)."""
BLOCK_BYTES = 256 * 1024
"""A block is written once it holds this many bytes of records (or a second has passed)."""
BLOCK_SECONDS = 1.0
"""Longest time recorded points stay in memory before their block is written [s]."""
MAX_BLOCK_BYTES = 256 * 1024 * 1024
"""The largest block a reader accepts (a block holds at least one whole record)."""
MAX_HEADER_BYTES = 16 * 1024 * 1024
"""The largest JSON header a reader accepts."""
_TOLERANCE = 1e-9
"""Relative tolerance when a run's times and steps are compared with the recorded grid."""


class Damaged(ValueError):
    """The file is not what the writer wrote (a checksum, a count or a gap)."""


@dataclass(frozen=True, kw_only=True)
class Grid:
    """The communication points of the recorded component: t_j = start + j * m * h."""

    start_time: float
    """t_0 of the recorded run [s]."""
    step_size: float
    """The run's base step h [s]."""
    multiple: int
    """The component's step multiple m."""
    component_step: float
    """The step size the component received (its deltaTime, else h) [s]."""


@dataclass(frozen=True)
class Block:
    """Where one block's records are: points ``first`` .. ``first + count - 1`` (and the end
    record, in the last block) in ``length`` bytes at ``offset``."""

    first: int
    count: int
    offset: int
    length: int
    crc: int


@dataclass(frozen=True, kw_only=True)
class Recording:
    """A recording's header and the index of its blocks; the points are read back block by
    block (``points``, ``rows``), never all at once."""

    path: Path
    component: str
    """The component name in the recorded scenario."""
    description: Description
    """What the participant declared."""
    grid: Grid
    outputs: tuple[Channel, ...]
    """Recorded outputs, in record order."""
    blocks: tuple[Block, ...]
    count: int
    """Communication points recorded."""
    end_time: float
    """t_j of the last point, as the recorded run computed it."""
    run_id: str = ""
    request: str | None = None
    """The component asked to end the run at its last point, with this reason; else None."""
    sealed: bool = True
    """False when the recorded run was killed: the file ends without its seal."""
    location: Path | None = None
    """``path`` made absolute when it was read: its blocks are read from there later, whatever
    the process's working folder is then (FMPy changes it while it loads an FMU's library, on
    another thread of the same run)."""

    @property
    def steps(self) -> int:
        """Component steps recorded (communication points - 1)."""
        return self.count - 1

    def points(self) -> Points:
        """A reader of the points, one block in memory at a time; close it when done."""
        return Points(self)

    def rows(self) -> Iterator[tuple[float, dict[str, Value]]]:
        """(t_j, outputs) for j = 0, 1, ..., streamed block by block."""
        with self.points() as points:
            for block in self.blocks:
                yield from points.block(block)

    def summary(self) -> str:
        """``recording P of C has t0=0 s, h=0.1 s, 600 steps to 60 s``, for messages."""
        grid = self.grid
        cut = "" if self.sealed else " (where the recorded run was killed)"
        return (
            f"recording {self.path} of {self.component} has t0={grid.start_time:g} s, "
            f"h={grid.component_step:g} s, {self.steps} steps to {self.end_time:g} s{cut}"
        )

    def grid_problem(self, start: float, step: float, stop: float | None) -> str | None:
        """Why a run with these times cannot be served from this recording, or None."""
        grid, asked = self.grid, []
        if not _same(start, grid.start_time):
            asked.append(f"t0={start:g} s")
        if not _same(step, grid.component_step):
            asked.append(f"h={step:g} s")
        if stop is not None and not asked:
            ratio = (stop - start) / step
            if not math.isclose(ratio, round(ratio), rel_tol=_TOLERANCE, abs_tol=_TOLERANCE):
                asked.append(f"a stop time of {stop:g} s, off its grid")
            elif round(ratio) > self.steps and self.request is None:
                asked.append(f"a stop time of {stop:g} s, beyond its end")
        if not asked:
            return None
        return (
            f"{self.summary()}; the run asks {' and '.join(asked)}: run with the recorded start "
            f"time and step (and a stop time within the recording), or record again"
        )

    def point(self, time: float, step: float) -> int:
        """The index j of the communication point a step from ``time`` by ``step`` ends at;
        ScenarioError (with the recorded grid) when the recording has no such step."""
        grid = self.grid
        ratio = (time - grid.start_time) / grid.component_step
        j = round(ratio)
        on_grid = math.isclose(ratio, j, rel_tol=_TOLERANCE, abs_tol=_TOLERANCE)
        if not on_grid or not _same(step, grid.component_step) or not 0 <= j < self.steps:
            raise ScenarioError(
                f"{self.summary()}; the run asks for a step from t={time:g} s by {step:g} s, "
                f"which it does not have"
            )
        return j + 1


class Points:
    """The points of a recording by index, read and checked one block at a time (the block
    of the last point asked for stays decoded: a replay asks for them in order)."""

    def __init__(self, recording: Recording) -> None:
        self.recording = recording
        self._starts = [b.first for b in recording.blocks]
        self._file: BinaryIO | None = None
        self._cached: Block | None = None
        self._rows: list[tuple[float, dict[str, Value]]] = []

    def __enter__(self) -> Points:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        self._cached, self._rows = None, []

    def holds(self, j: int) -> bool:
        """Whether point ``j`` is in the block decoded now (``at`` reads nothing)."""
        block = self._cached
        return block is not None and block.first <= j < block.first + block.count

    def at(self, j: int) -> dict[str, Value]:
        """The outputs at point ``j`` (0 <= j < count)."""
        block = self.recording.blocks[bisect.bisect_right(self._starts, j) - 1]
        if block is not self._cached:
            self._rows = self.block(block)
            self._cached = block
        return self._rows[j - block.first][1]

    def block(self, block: Block) -> list[tuple[float, dict[str, Value]]]:
        """The points of ``block``, read again and checked; ScenarioError if the file changed."""
        path = self.recording.path
        try:
            if self._file is None:
                self._file = (self.recording.location or path).open("rb")
            self._file.seek(block.offset)
            payload = self._file.read(block.length)
            if len(payload) != block.length or zlib.crc32(payload) != block.crc:
                raise Damaged(f"{_where(block)} changed since the file was opened")
            return _records(self.recording.outputs, payload, block)[0]
        except OSError as exc:
            raise ScenarioError(f"cannot read the recording {path}: {exc.strerror or exc}") from exc
        except (Damaged, ValueError, struct.error) as exc:
            raise _unreadable(path, exc) from exc


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=_TOLERANCE, abs_tol=_TOLERANCE)


def locate(path: Path, component: str | None) -> Path:
    """The recording file of ``component`` at ``path``: the file itself, or
    ``PATH/recordings/C.crec`` (a results directory), or ``PATH/C.crec``; with no component
    named, a directory's only recording. A results directory's recording must be its own run's
    (its summary.json lists it): a file another run left there is refused."""
    if path.is_dir():
        if component is None:
            found = sorted({*path.glob(f"recordings/*{SUFFIX}"), *path.glob(f"*{SUFFIX}")})
            if len(found) == 1:
                return _own(path, found[0])
            names = ", ".join(p.stem for p in found) or "none"
            raise ScenarioError(
                f"{path} holds {len(found)} recordings ({names}); name the component "
                f"(--component C, or replay:PATH#C){_runs_inside(path)}"
            )
        for candidate in (
            path / "recordings" / f"{component}{SUFFIX}",
            path / f"{component}{SUFFIX}",
        ):
            if candidate.is_file():
                return _own(path, candidate)
        raise ScenarioError(
            f"no recording of '{component}' in {path} (looked for recordings/{component}{SUFFIX} "
            f"and {component}{SUFFIX}); record it with coupler run --record {component}"
            f"{_runs_inside(path)}"
        )
    if not path.is_file():
        raise ScenarioError(
            f"recording {path} does not exist; record one with coupler run --record COMPONENT"
        )
    return path


def _own(results: Path, found: Path) -> Path:
    """``found``, unless ``results`` holds a run's results (summary.json) that did not record
    it: then it is another run's file, and replaying it would mix two runs."""
    try:
        summary = json.loads((results / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return found
    own = summary.get("recordings", {}) if isinstance(summary, dict) else {}
    if found.parent == results / "recordings" and own.get(found.stem) != (
        f"recordings/{found.name}"
    ):
        raise ScenarioError(
            f"{found} is not a recording of the run whose results are in {results} (run "
            f"{summary.get('run_id', '?')} did not --record {found.stem}): another run left it "
            f"there. Replay the results folder of the run that recorded it, or the .crec file "
            f"itself if you are sure"
        )
    return found


def _runs_inside(path: Path) -> str:
    """A hint when ``path`` is a base folder holding runs of their own (``latest``)."""
    latest = path / "latest"
    if latest.is_dir():
        return f"; {path} holds one folder per run: give one of them, e.g. {latest}"
    return ""


class Recorder(Observer):
    """Writes one component's outputs at each of its communication points to ``path``: every
    output it describes, whatever the results select, in checksummed blocks."""

    def __init__(
        self, path: Path, description: Description, *, component: str, multiple: int, step: float
    ) -> None:
        self.path = path
        self.description = description
        self.component = component
        self.multiple = multiple
        """Its step multiple m: it is recorded every m-th base communication point."""
        self.step = step
        """The step size it receives [s]."""
        self.outputs = description.of(Causality.OUTPUT)
        self._file: BinaryIO | None = None
        self._slots: list[int] = []
        self._count = 0
        self._block = bytearray()
        self._first = 0
        """j of the first point in ``_block``."""
        self._records = 0
        """Records in ``_block``."""
        self._written = 0.0

    def started(self, info: RunInfo) -> None:
        names = [c.name for c in info.columns]
        self._slots = [names.index(f"{self.component}.{c.name}") for c in self.outputs]
        header = {
            "format": "coupler-recording",
            "version": VERSION,
            "component": self.component,
            "run_id": info.run_id,
            "grid": {
                "start_time": info.start_time,
                "step_size": info.step_size,
                "multiple": self.multiple,
                "component_step": self.step,
                "planned_stop_time": info.stop_time,
            },
            "description": _description_to_json(self.description),
            "outputs": [c.name for c in self.outputs],
        }
        data = json.dumps(header, indent=1).encode("utf-8")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = self.path.open("wb", buffering=0)  # a block is one write
            self._file.write(_PREFIX.pack(MAGIC, VERSION, len(data), zlib.crc32(data)) + data)
        except OSError as exc:
            raise CouplerError(f"cannot write the recording {self.path}: {exc}") from exc
        self._count, self._first, self._records = 0, 0, 0
        self._block.clear()
        self._written = wallclock.monotonic()

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        k, self._count = self._count, self._count + 1
        if self._file is None or k % self.multiple:
            return
        parts = [_POINT.pack(k // self.multiple, time)]
        for channel, slot in zip(self.outputs, self._slots, strict=True):
            parts.append(_encode(channel.type, row[slot]))
        self._add(b"".join(parts))

    def closing(self, end: RunEnd) -> None:
        """Write the last block and the seal; when this component ended the run, its request
        closes the records (a record with j = ``END``: the end time and the reason, a String)."""
        if self._file is None:
            return
        try:
            if end.ended_by == self.component:
                record = _POINT.pack(END, end.end_time) + _encode(ValueType.STRING, end.request)
                self._add(record, end=True)
            points = self._first + self._records
            self._write_block()
            self._write(_block_head(0, points, 0, zlib.crc32(b"")))  # the seal
        finally:
            self._file.close()
            self._file = None

    def _add(self, record: bytes, *, end: bool = False) -> None:
        if len(record) + _BLOCK_HEAD > MAX_BLOCK_BYTES:
            raise CouplerError(
                f"cannot write the recording {self.path}: one point of {self.component} takes "
                f"{len(record)} bytes, more than a recording block may hold ({MAX_BLOCK_BYTES})"
            )
        self._block += _LENGTH.pack(len(record))
        self._block += record
        if not end:
            self._records += 1
        if len(self._block) >= BLOCK_BYTES or wallclock.monotonic() - self._written >= 1.0:
            self._write_block()

    def _write_block(self) -> None:
        if not self._block:
            return
        payload = bytes(self._block)
        self._write(_block_head(len(payload), self._first, self._records, zlib.crc32(payload)))
        self._write(payload)
        self._first += self._records
        self._records = 0
        self._block.clear()
        self._written = wallclock.monotonic()

    def _write(self, data: bytes) -> None:
        assert self._file is not None
        try:
            self._file.write(data)
        except OSError as exc:
            raise CouplerError(f"cannot write the recording {self.path}: {exc}") from exc


def _block_head(length: int, first: int, count: int, crc: int) -> bytes:
    head = _BLOCK.pack(length, first, count, crc)
    return head + _LENGTH.pack(zlib.crc32(head))


def read(path: Path) -> Recording:
    """The recording at ``path``, every block's checksums checked, reading one block at a
    time; ScenarioError when it is not one this version can read, or is damaged."""
    location = Path(os.path.abspath(path))
    try:
        with location.open("rb") as file:
            return dataclasses.replace(_index(path, file), location=location)
    except OSError as exc:
        raise ScenarioError(f"cannot read the recording {path}: {exc.strerror or exc}") from exc
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError, struct.error) as exc:
        raise _unreadable(path, exc) from exc


def _unreadable(path: Path, exc: Exception) -> ScenarioError:
    if isinstance(exc, Damaged):
        return ScenarioError(
            f"{path} is damaged: {exc}; the file changed after it was recorded (a disk or a "
            f"copy went wrong, or someone edited it) - use an intact copy or record it again "
            f"with coupler run --record COMPONENT"
        )
    return ScenarioError(
        f"{path} is not a readable Coupler recording ({exc}); record it again with "
        f"coupler run --record COMPONENT"
    )


def _where(block: Block) -> str:
    return f"the block of points {block.first}.. at byte {block.offset - _BLOCK_HEAD}"


def _index(path: Path, file: BinaryIO) -> Recording:
    """Read the header, then every block (checking its checksums), keeping only its place;
    the first and last blocks are decoded too (the start values, the end and its request)."""
    prefix = file.read(_PREFIX.size)
    if len(prefix) < 6:
        raise ValueError("too short")
    magic, version = struct.unpack_from("<4sH", prefix)
    if magic != MAGIC:
        raise ValueError("no CREC signature")
    if version != VERSION:
        raise ValueError(
            f"format version {version}; this Coupler reads version {VERSION} only (version 1, "
            "without checksums, is no longer read)"
        )
    if len(prefix) < _PREFIX.size:
        raise ValueError("too short")
    _, _, size, crc = _PREFIX.unpack(prefix)
    if size > MAX_HEADER_BYTES:
        raise Damaged(f"its header claims {size} bytes, more than {MAX_HEADER_BYTES}")
    data = file.read(size)
    if len(data) != size or zlib.crc32(data) != crc:
        raise Damaged("its header does not match its checksum")
    header: dict[str, Any] = json.loads(data.decode("utf-8"))
    description = _description_from_json(header["description"])
    by_name = {c.name: c for c in description.channels}
    outputs = tuple(by_name[name] for name in header["outputs"])
    g = header["grid"]
    grid = Grid(
        start_time=float(g["start_time"]),
        step_size=float(g["step_size"]),
        multiple=int(g["multiple"]),
        component_step=float(g["component_step"]),
    )
    blocks, sealed = _blocks(file, _PREFIX.size + size)
    with_points = [b for b in blocks if b.count]
    if not with_points:
        raise ValueError("no communication point recorded")
    request, end_time = None, None
    for block in blocks[-2:]:  # the last points, and the end record (maybe a block of its own)
        file.seek(block.offset)
        rows, said = _records(outputs, file.read(block.length), block)
        end_time = rows[-1][0] if rows else end_time
        request = said or request
    if end_time is None:
        raise Damaged("its last blocks hold no point")
    return Recording(
        path=path,
        component=str(header["component"]),
        description=description,
        grid=grid,
        outputs=outputs,
        blocks=tuple(with_points),
        count=with_points[-1].first + with_points[-1].count,
        end_time=end_time,
        run_id=str(header.get("run_id", "")),
        request=request,
        sealed=sealed,
    )


def _blocks(file: BinaryIO, offset: int) -> tuple[list[Block], bool]:
    """Every block from ``offset`` on, its checksums checked; whether the seal ends them."""
    blocks: list[Block] = []
    expected = 0
    while True:
        head = file.read(_BLOCK_HEAD)
        if len(head) < _BLOCK_HEAD:
            return blocks, False  # the end of a file whose run was killed
        length, first, count, crc = _BLOCK.unpack_from(head)
        (check,) = _LENGTH.unpack_from(head, _BLOCK.size)
        here = Block(first, count, offset + _BLOCK_HEAD, length, crc)
        if zlib.crc32(head[: _BLOCK.size]) != check:
            raise Damaged(f"the block header at byte {offset} does not match its checksum")
        if first != expected:
            raise Damaged(f"{_where(here)} follows point {expected - 1}: points are missing")
        if length == 0 and count == 0:  # the seal
            if file.read(1):
                raise Damaged(f"bytes follow the seal at byte {offset}")
            return blocks, True
        if length > MAX_BLOCK_BYTES:
            raise Damaged(f"{_where(here)} claims {length} bytes, more than {MAX_BLOCK_BYTES}")
        payload = file.read(length)
        if len(payload) < length:
            return blocks, False  # cut off while it was written: the run was killed
        if zlib.crc32(payload) != crc:
            raise Damaged(f"{_where(here)} does not match its checksum")
        blocks.append(here)
        expected = first + count
        offset += _BLOCK_HEAD + length


def _records(
    outputs: Sequence[Channel], payload: bytes, block: Block
) -> tuple[list[tuple[float, dict[str, Value]]], str | None]:
    """The points of one block, and the end record's reason when it holds one."""
    rows: list[tuple[float, dict[str, Value]]] = []
    request: Value | None = None
    offset = 0
    while offset < len(payload):
        (length,) = _LENGTH.unpack_from(payload, offset)
        end = offset + _LENGTH.size + length
        if end > len(payload) or request is not None:
            raise ValueError(f"{_where(block)} holds a record that runs past it")
        j, time = _POINT.unpack_from(payload, offset + _LENGTH.size)
        at = offset + _LENGTH.size + _POINT.size
        if j == END:
            request, at = _decode(ValueType.STRING, payload, at)
        elif j != block.first + len(rows):
            raise ValueError(f"point {j} where {block.first + len(rows)} was expected")
        else:
            row: dict[str, Value] = {}
            for channel in outputs:
                row[channel.name], at = _decode(channel.type, payload, at)
            rows.append((time, row))
        if at != end:
            raise ValueError(f"the record of point {j} has {end - at} stray bytes")
        offset = end
    if len(rows) != block.count:
        raise ValueError(f"{_where(block)} holds {len(rows)} points, its header {block.count}")
    return rows, None if request is None else str(request)


def _encode(kind: ValueType, value: Value) -> bytes:
    if kind is ValueType.REAL:
        return _REAL.pack(value)
    if kind in (ValueType.INTEGER, ValueType.ENUMERATION):
        return _INT.pack(value)
    if kind is ValueType.BOOLEAN:
        return _BOOL.pack(1 if value else 0)
    raw = value.encode("utf-8") if isinstance(value, str) else bytes(value)
    return _LENGTH.pack(len(raw)) + raw


def _decode(kind: ValueType, data: bytes, at: int) -> tuple[Value, int]:
    if kind is ValueType.REAL:
        return _REAL.unpack_from(data, at)[0], at + _REAL.size
    if kind in (ValueType.INTEGER, ValueType.ENUMERATION):
        return _INT.unpack_from(data, at)[0], at + _INT.size
    if kind is ValueType.BOOLEAN:
        return bool(_BOOL.unpack_from(data, at)[0]), at + _BOOL.size
    (n,) = _LENGTH.unpack_from(data, at)
    raw = data[at + _LENGTH.size : at + _LENGTH.size + n]
    if len(raw) != n:
        raise ValueError("a value runs past the end of its record")
    end = at + _LENGTH.size + n
    return (raw.decode("utf-8") if kind is ValueType.STRING else raw), end


def _description_to_json(description: Description) -> dict[str, Any]:
    caps = description.capabilities
    return {
        "name": description.name,
        "implementation": description.implementation,
        "capabilities": {
            "streaming": caps.streaming,
            "variable_step_size": caps.variable_step_size,
            "fixed_step_size": caps.fixed_step_size,
        },
        "channels": [
            {
                "name": c.name,
                "causality": str(c.causality),
                "type": str(c.type),
                "unit": c.unit,
                "message_type": c.message_type,
                "description": c.description,
                "start": c.start.hex() if isinstance(c.start, bytes) else c.start,
                **({"max_bytes": c.max_bytes} if c.max_bytes else {}),
            }
            for c in description.channels
        ],
    }


def _description_from_json(data: dict[str, Any]) -> Description:
    channels = []
    for c in data["channels"]:
        kind = ValueType(c["type"])
        start = c.get("start")
        if start is not None and kind is ValueType.BINARY:
            start = bytes.fromhex(start)
        channels.append(
            Channel(
                name=c["name"],
                causality=Causality(c["causality"]),
                type=kind,
                unit=c.get("unit", ""),
                message_type=c.get("message_type", ""),
                description=c.get("description", ""),
                start=start,
                max_bytes=int(c.get("max_bytes", 0)),
            )
        )
    caps = data.get("capabilities", {})
    return Description(
        name=data["name"],
        channels=tuple(channels),
        capabilities=Capabilities(
            streaming=bool(caps.get("streaming", True)),
            variable_step_size=bool(caps.get("variable_step_size", True)),
            fixed_step_size=float(caps.get("fixed_step_size", 0.0)),
        ),
        implementation=data.get("implementation", ""),
    )
