"""Recordings of one participant's outputs (``coupler run --record``), and reading them back.

A recording holds, for one component, every output at every one of its communication points,
lossless and typed (Real as the float64 bits, Integer, Boolean, String, Binary with its message
type), the time grid of the run and the participant's declared channels. ``coupler.replay``
serves it again. docs/replay.md describes the file format (``.crec``), version 1::

    b"CREC"  u16 version  u32 N  N bytes of UTF-8 JSON header
    then per communication point j = 0, 1, ...:  u32 L  L bytes:
        u64 j  f64 time  each output in header order:
            Real f64 | Integer, Enumeration i64 | Boolean u8 | String, Binary u32 n + n bytes

little-endian throughout; when the component asked to end the run, a last record with
j = 2**64 - 1 holds the time and its reason (a String). Records are appended as the run goes:
a run that is killed leaves every complete record readable (a trailing partial one is
ignored).
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from coupler.channels import Capabilities, Causality, Channel, Description, Value, ValueType
from coupler.errors import CouplerError, ScenarioError
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo

MAGIC = b"CREC"
VERSION = 1
SUFFIX = ".crec"
_PREFIX = struct.Struct("<4sHI")
_LENGTH = struct.Struct("<I")
_POINT = struct.Struct("<Qd")
_REAL, _INT, _BOOL = struct.Struct("<d"), struct.Struct("<q"), struct.Struct("<B")
END = 2**64 - 1
"""j of the record saying the component asked to end the run there (after the last point)."""
_TOLERANCE = 1e-9
"""Relative tolerance when a run's times and steps are compared with the recorded grid."""


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


@dataclass(frozen=True, kw_only=True)
class Recording:
    """A recording read back: header and every complete communication point."""

    path: Path
    component: str
    """The component name in the recorded scenario."""
    description: Description
    """What the participant declared."""
    grid: Grid
    outputs: tuple[Channel, ...]
    """Recorded outputs, in record order."""
    times: tuple[float, ...]
    """t_j as the recorded run computed them."""
    values: tuple[dict[str, Value], ...]
    """Outputs at t_j, by channel name."""
    run_id: str = ""
    request: str | None = None
    """The component asked to end the run at its last point, with this reason; else None."""

    @property
    def steps(self) -> int:
        """Component steps recorded (communication points - 1)."""
        return len(self.times) - 1

    @property
    def end_time(self) -> float:
        return self.times[-1]

    def summary(self) -> str:
        """``recording P of C has t0=0 s, h=0.1 s, 600 steps to 60 s``, for messages."""
        grid = self.grid
        return (
            f"recording {self.path} of {self.component} has t0={grid.start_time:g} s, "
            f"h={grid.component_step:g} s, {self.steps} steps to {self.end_time:g} s"
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
    output it describes, whatever the results select."""

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
            self._file = self.path.open("wb")
            self._file.write(_PREFIX.pack(MAGIC, VERSION, len(data)) + data)
        except OSError as exc:
            raise CouplerError(f"cannot write the recording {self.path}: {exc}") from exc
        self._count = 0

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        k, self._count = self._count, self._count + 1
        if self._file is None or k % self.multiple:
            return
        parts = [_POINT.pack(k // self.multiple, time)]
        for channel, slot in zip(self.outputs, self._slots, strict=True):
            parts.append(_encode(channel.type, row[slot]))
        record = b"".join(parts)
        try:
            self._file.write(_LENGTH.pack(len(record)) + record)
        except OSError as exc:
            raise CouplerError(f"cannot write the recording {self.path}: {exc}") from exc

    def finished(self, end: RunEnd) -> None:
        """Close the file; when this component ended the run, its request closes the records
        (a record with j = ``END``: the end time and the reason, as a String)."""
        if self._file is None:
            return
        try:
            if end.ended_by == self.component:
                record = _POINT.pack(END, end.end_time) + _encode(ValueType.STRING, end.request)
                self._file.write(_LENGTH.pack(len(record)) + record)
        except OSError as exc:
            raise CouplerError(f"cannot write the recording {self.path}: {exc}") from exc
        finally:
            self._file.close()
            self._file = None


def read(path: Path) -> Recording:
    """The recording at ``path``; ScenarioError when it is not one this version can read."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ScenarioError(f"cannot read the recording {path}: {exc.strerror or exc}") from exc
    try:
        return _parse(path, data)
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError, struct.error) as exc:
        raise ScenarioError(
            f"{path} is not a readable Coupler recording ({exc}); record it again with "
            f"coupler run --record COMPONENT"
        ) from exc


def _parse(path: Path, data: bytes) -> Recording:
    if len(data) < _PREFIX.size:
        raise ValueError("too short")
    magic, version, size = _PREFIX.unpack_from(data)
    if magic != MAGIC:
        raise ValueError("no CREC signature")
    if version != VERSION:
        raise ValueError(f"format version {version}, this Coupler reads version {VERSION}")
    offset = _PREFIX.size + size
    header: dict[str, Any] = json.loads(data[_PREFIX.size : offset].decode("utf-8"))
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
    times: list[float] = []
    values: list[dict[str, Value]] = []
    request: Value | None = None
    while offset + _LENGTH.size <= len(data):
        (length,) = _LENGTH.unpack_from(data, offset)
        end = offset + _LENGTH.size + length
        if end > len(data):
            break  # the run was killed while writing this record
        j, time = _POINT.unpack_from(data, offset + _LENGTH.size)
        if j == END and times:
            request, at = _decode(ValueType.STRING, data, offset + _LENGTH.size + _POINT.size)
            if at != end:
                raise ValueError("the end record has stray bytes")
            offset = end
            break
        if j != len(times):
            raise ValueError(f"communication point {j} where {len(times)} was expected")
        at = offset + _LENGTH.size + _POINT.size
        row: dict[str, Value] = {}
        for channel in outputs:
            row[channel.name], at = _decode(channel.type, data, at)
        if at != end:
            raise ValueError(f"record {j} has {end - at} stray bytes")
        times.append(time)
        values.append(row)
        offset = end
    if not times:
        raise ValueError("no communication point recorded")
    return Recording(
        path=path,
        component=str(header["component"]),
        description=description,
        grid=grid,
        outputs=outputs,
        times=tuple(times),
        values=tuple(values),
        run_id=str(header.get("run_id", "")),
        request=None if request is None else str(request),
    )


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
