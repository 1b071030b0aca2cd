"""OpenMCx's result files beside results.csv (``coupler run --openmcx-results``), so that what
reads OpenMCx's results reads Coupler's: per component ``<Component>_res.csv`` (its outputs)
and ``<Component>_in.csv`` (its inputs), as OpenMCx's CSV backend writes them (its
``storage/StorageBackendCsv.c``):

- line 1 ``sep=,``; line 2 ``"Time"`` and the SSD connector names, double-quoted (a vector's
  elements ``v[1]`` ...); line 3 the units: ``s``, then the connector's unit, ``-`` for a Real
  without one, ``(null)`` for Integer, Boolean and String ports;
- one row per time: Reals ``%.13E``, Integers ``%d``, Booleans ``0``/``1``, Strings quoted;
- ``_res``: the outputs at the start and at the end of every step of the component (at its own
  times when it has its own step); ``_in``: the inputs it read for each step, stamped with the
  step's start (its end with ``inputAtEndTime``), and once more at the end;
- a port with ``writeResults="false"``, and an input neither connected nor defaulted, has no
  column; a component without columns has no file. The file name is the component's, with each
  of ``\\"<>|!#$&'()*+,/:;=?@[]%`` written ``%`` and two hex digits.

It needs a run with OpenMCx's semantics (it is told each component's own steps).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from coupler.channels import Value, ValueType
from coupler.errors import CouplerError
from coupler_orchestrator import ssp
from coupler_orchestrator.observer import ComponentObserver, RunEnd, RunInfo
from coupler_orchestrator.options import RunOptions

_ENCODED = set("\\\"<>|!#$&'()*+,/:;=?@[]%")


def file_name(component: str) -> str:
    """OpenMCx's file name for a component name (its ``mcx_string_encode_filename``)."""
    return "".join(f"%{ord(c):02x}" if c in _ENCODED else c for c in component)


@dataclass(frozen=True)
class _Column:
    name: str
    """The SSD connector."""
    channel: str
    """The participant's channel."""
    type: ValueType
    unit: str


def _unit(connector: ssp.Connector) -> str:
    if connector.type not in (None, ValueType.REAL):
        return "(null)"
    return connector.unit or "-"


def _text(value: Value, type_: ValueType) -> str:
    if type_ is ValueType.REAL:
        return f"{float(value):.13E}"
    if type_ is ValueType.BOOLEAN:
        return "1" if value else "0"
    if type_ in (ValueType.INTEGER, ValueType.ENUMERATION):
        return str(int(value))
    text = value.hex() if isinstance(value, bytes) else str(value)
    return '"' + text.replace('"', '""') + '"'


class _File:
    def __init__(self, path: Path, columns: list[_Column]) -> None:
        self.path = path
        self.columns = columns
        self.file: IO[str] | None = None

    def open(self) -> None:
        self.file = self.path.open("w", encoding="utf-8", newline="\n")
        quoted = ",".join('"' + c.name.replace('"', '""') + '"' for c in self.columns)
        self.file.write(f'sep=,\n"Time",{quoted}\ns,{",".join(c.unit for c in self.columns)}\n')

    def row(self, time: float, values: Mapping[str, Value]) -> None:
        assert self.file is not None
        cells = ",".join(_text(values[c.channel], c.type) for c in self.columns)
        try:
            self.file.write(f"{time:.13E},{cells}\n")
        except OSError as exc:
            raise CouplerError(f"cannot write {self.path}: {exc.strerror or exc}") from exc

    def close(self) -> None:
        file, self.file = self.file, None
        if file is not None:
            file.close()


def openmcx_results(
    directory: Path, scenario: ssp.Scenario, options: RunOptions
) -> list[OpenMcxResults]:
    """The writer of OpenMCx's result files into ``directory`` when the options ask for them
    (``--openmcx-results``); none else."""
    return [OpenMcxResults(directory, scenario)] if options.openmcx_results else []


class OpenMcxResults(ComponentObserver):
    """Writes OpenMCx's result files of the scenario's components into ``directory``."""

    def __init__(self, directory: Path, scenario: ssp.Scenario) -> None:
        self.directory = directory
        self.outputs: dict[str, _File] = {}
        self.inputs: dict[str, _File] = {}
        driven = {c.end for c in scenario.connections}
        for component in scenario.components:
            outs, ins = [], []
            for c in component.connectors:
                if c.port is not None and not c.port.write_results:
                    continue
                column = _Column(c.name, c.channel, c.type or ValueType.REAL, _unit(c))
                if c.kind == "output":
                    outs.append(column)
                elif c.kind == "input" and (
                    f"{component.name}.{c.name}" in driven
                    or (c.port is not None and c.port.default is not None)
                ):
                    ins.append(column)
            stem = file_name(component.name)
            if outs:
                self.outputs[component.name] = _File(directory / f"{stem}_res.csv", outs)
            if ins:
                self.inputs[component.name] = _File(directory / f"{stem}_in.csv", ins)

    @property
    def paths(self) -> list[Path]:
        """The files written, outputs first."""
        return [f.path for f in (*self.outputs.values(), *self.inputs.values())]

    def started(self, info: RunInfo) -> None:
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            for f in (*self.outputs.values(), *self.inputs.values()):
                f.open()
        except OSError as exc:
            raise CouplerError(
                f"cannot write OpenMCx's result files into {self.directory}: {exc}"
            ) from exc

    def component_outputs(self, component: str, time: float, values: Mapping[str, Value]) -> None:
        f = self.outputs.get(component)
        if f is not None:
            f.row(time, values)

    def component_inputs(self, component: str, time: float, values: Mapping[str, Value]) -> None:
        f = self.inputs.get(component)
        if f is not None:
            f.row(time, values)

    def closing(self, end: RunEnd) -> None:
        problem = None
        for f in (*self.outputs.values(), *self.inputs.values()):
            try:
                f.close()
            except OSError as exc:
                problem = problem or exc
        if problem is not None:
            raise CouplerError(
                f"cannot write OpenMCx's result files into {self.directory}: {problem}"
            ) from problem
