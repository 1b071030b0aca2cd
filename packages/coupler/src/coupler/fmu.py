"""``FmuParticipant``: an FMU (FMI 1.0, 2.0 or 3.0 co-simulation) run in-process through FMPy.

Blocking FMI calls run on one worker thread per FMU, off the event loop. A failing FMI call
becomes a ``ParticipantError`` carrying the FMU, the call and the FMI status (``_fmi_call``, the
one place FMPy's errors are translated).
"""

from __future__ import annotations

import asyncio
import ctypes
import shutil
import tempfile
import threading
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, TypeVar

import fmpy
from fmpy.fmi1 import FMICallException
from fmpy.model_description import ModelDescription, ScalarVariable

from coupler.channels import (
    Capabilities,
    Causality,
    Channel,
    Description,
    RunSetup,
    Value,
    ValueType,
)
from coupler.errors import ParticipantError, ScenarioError
from coupler.participant import Participant, Values
from coupler.values import coerce

T = TypeVar("T")

_VALUE_TYPES = {
    "Real": ValueType.REAL,
    "Float64": ValueType.REAL,
    "Float32": ValueType.REAL,
    "Integer": ValueType.INTEGER,
    "Int8": ValueType.INTEGER,
    "UInt8": ValueType.INTEGER,
    "Int16": ValueType.INTEGER,
    "UInt16": ValueType.INTEGER,
    "Int32": ValueType.INTEGER,
    "UInt32": ValueType.INTEGER,
    "Int64": ValueType.INTEGER,
    "UInt64": ValueType.INTEGER,
    "Boolean": ValueType.BOOLEAN,
    "String": ValueType.STRING,
    "Binary": ValueType.BINARY,
    "Enumeration": ValueType.ENUMERATION,
}
_CAUSALITIES = {
    "input": Causality.INPUT,
    "output": Causality.OUTPUT,
    "parameter": Causality.PARAMETER,
    "structuralParameter": Causality.PARAMETER,
}
_STATUS = ["OK", "Warning", "Discard", "Error", "Fatal", "Pending"]

#: FMPy 0.3.32 declares these FMI 1.0 co-simulation functions as returning fmiString, not
#: fmiStatus: any status but fmiOK would be read as a char pointer (a crash, never an error).
_FMI1_STATUS_FUNCTIONS = (
    "fmi1InitializeSlave",
    "fmi1DoStep",
    "fmi1CancelStep",
    "fmi1SetRealInputDerivatives",
    "fmi1GetRealOutputDerivatives",
    "fmi1GetStatus",
    "fmi1GetRealStatus",
    "fmi1GetIntegerStatus",
    "fmi1GetBooleanStatus",
    "fmi1GetStringStatus",
)

#: FMPy's FMU constructor changes the process's working directory to the binary's folder and
#: back; FMUs loaded concurrently (Jacobi initializes everyone at once) must take turns.
_LOAD_LOCK = threading.Lock()


@dataclass(frozen=True)
class _Group:
    """Variables of one FMI type, read or written with one call."""

    fmi_type: str
    names: tuple[str, ...]
    refs: tuple[int, ...]


def _accessor(fmi_version: str, fmi_type: str) -> str:
    """Name of the FMPy getter/setter suffix for an FMI type."""
    if fmi_version == "3.0":
        return "Int64" if fmi_type == "Enumeration" else fmi_type
    return "Integer" if fmi_type == "Enumeration" else fmi_type


def _parse_start(fmi_type: str, text: str | None) -> Value | None:
    if text is None:
        return None
    value_type = _VALUE_TYPES[fmi_type]
    if value_type is ValueType.REAL:
        return float(text)
    if value_type in (ValueType.INTEGER, ValueType.ENUMERATION):
        return int(text)
    if value_type is ValueType.BOOLEAN:
        return text.strip().lower() in ("true", "1")
    if value_type is ValueType.BINARY:
        return bytes.fromhex(text)
    return text


def _unit(variable: ScalarVariable) -> str:
    unit = variable.unit or (variable.declaredType.unit if variable.declaredType else None)
    return unit or ""


class FmuParticipant(Participant):
    """An FMU as a participant. ``path`` is the .fmu file; ``name`` defaults to its model name."""

    def __init__(self, path: str | Path, *, name: str | None = None) -> None:
        self.path = Path(path)
        self._name = name
        self._md: ModelDescription | None = None
        self._unzipdir: str | None = None
        self._executor: ThreadPoolExecutor | None = None
        self._slave: Any = None
        self._variables: dict[str, ScalarVariable] = {}
        self._outputs: list[_Group] = []
        self._group_cache: dict[tuple[str, ...], list[_Group]] = {}

    @property
    def name(self) -> str:
        return self._name or (self._md.modelName if self._md else self.path.stem)

    async def open(self) -> None:
        if self._md is not None:
            return
        if not self.path.is_file():
            raise ScenarioError(f"FMU not found: {self.path} (check the component's source)")
        try:
            md = fmpy.read_model_description(str(self.path), validate=False)
        except Exception as exc:
            raise ScenarioError(f"{self.path}: not a readable FMU: {exc}") from exc
        if md.coSimulation is None:
            raise ScenarioError(
                f"{self.path}: FMU '{md.modelName}' has no co-simulation interface "
                f"(Coupler runs co-simulation FMUs; export it for co-simulation)"
            )
        self._md = md
        self._unzipdir = fmpy.extract(
            str(self.path), unzipdir=tempfile.mkdtemp(prefix="coupler-fmu-")
        )
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"fmu-{md.modelName}")
        self._variables = {
            v.name: v
            for v in md.modelVariables
            if v.causality in _CAUSALITIES and v.type in _VALUE_TYPES
        }
        self._outputs = self._groups(
            v.name for v in self._variables.values() if v.causality == "output"
        )

    async def close(self) -> None:
        await self._free()
        if self._executor is not None:
            self._executor.shutdown(wait=True)
            self._executor = None
        if self._unzipdir is not None:
            shutil.rmtree(self._unzipdir, ignore_errors=True)
            self._unzipdir = None
        self._md = None

    @property
    def model_description(self) -> ModelDescription:
        if self._md is None:
            raise ParticipantError("FMU not opened", participant=self.name, call="describe")
        return self._md

    async def describe(self) -> Description:
        await self.open()
        md = self.model_description
        return Description(
            name=self.name,
            implementation=f"FMI {md.fmiVersion} FMU {md.modelName} "
            f"({md.generationTool or 'unknown tool'}) via FMPy {fmpy.__version__}",
            capabilities=Capabilities(
                streaming=True,
                variable_step_size=bool(md.coSimulation.canHandleVariableCommunicationStepSize),
            ),
            channels=tuple(
                Channel(
                    name=v.name,
                    causality=_CAUSALITIES[v.causality],
                    type=_VALUE_TYPES[v.type],
                    unit=_unit(v),
                    start=_parse_start(v.type, v.start),
                    description=v.description or "",
                )
                for v in self._variables.values()
            ),
        )

    async def initialize(self, setup: RunSetup) -> Values:
        await self.open()
        await self._free()
        md = self.model_description
        version = md.fmiVersion
        start, stop = setup.start_time, setup.stop_time

        def init() -> Values:
            with _LOAD_LOCK:
                slave = fmpy.instantiate_fmu(self._unzipdir, md, fmi_type="CoSimulation")
            if version == "1.0":
                self._check_fmi1_slave(slave)
            self._slave = slave
            if version == "2.0":
                self._fmi(
                    "fmi2SetupExperiment",
                    lambda: self._slave.setupExperiment(startTime=start, stopTime=stop),
                )
            self._set({**setup.parameters, **setup.inputs})
            if version == "1.0":
                self._fmi(
                    "fmiInitializeSlave",
                    lambda: self._slave.initialize(tStart=start, stopTime=stop),
                )
            elif version == "2.0":
                self._fmi("fmi2EnterInitializationMode", self._slave.enterInitializationMode)
                self._fmi("fmi2ExitInitializationMode", self._slave.exitInitializationMode)
            else:
                self._fmi(
                    "fmi3EnterInitializationMode",
                    lambda: self._slave.enterInitializationMode(startTime=start, stopTime=stop),
                )
                self._fmi("fmi3ExitInitializationMode", self._slave.exitInitializationMode)
            return self._get_outputs()

        return await self._run(init)

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        version = self.model_description.fmiVersion

        def step_fmu() -> Values:
            self._require_instance("DoStep")
            self._set(inputs)
            result = self._fmi(
                f"{_prefix(version)}DoStep",
                lambda: self._slave.doStep(
                    currentCommunicationPoint=time, communicationStepSize=step
                ),
            )
            if version == "3.0" and result[1]:
                raise ParticipantError(
                    f"FMU requested to terminate the simulation at t={time + step:g}",
                    participant=self.name,
                    call="fmi3DoStep",
                    status="terminateSimulation",
                )
            return self._get_outputs()

        return await self._run(step_fmu)

    async def terminate(self, reason: str = "") -> None:
        await self._free(terminate=True)

    # --- FMI plumbing, run on the worker thread ----------------------------------------------

    def _groups(self, names: Iterable[str]) -> list[_Group]:
        by_type: dict[str, list[ScalarVariable]] = {}
        for name in names:
            variable = self._variables[name]
            by_type.setdefault(variable.type, []).append(variable)
        return [
            _Group(t, tuple(v.name for v in vs), tuple(v.valueReference for v in vs))
            for t, vs in by_type.items()
        ]

    def _input_groups(self, names: tuple[str, ...]) -> list[_Group]:
        """Groups for a set of names; the step loop asks for the same set every step."""
        groups = self._group_cache.get(names)
        if groups is None:
            groups = self._group_cache[names] = self._groups(names)
        return groups

    def _set(self, values: Mapping[str, Value]) -> None:
        unknown = [n for n in values if n not in self._variables]
        if unknown:
            raise ScenarioError(
                f"FMU '{self.name}' has no input or parameter {', '.join(map(repr, unknown))}"
            )
        version = self.model_description.fmiVersion
        for group in self._input_groups(tuple(values)):
            converted = [coerce(_VALUE_TYPES[group.fmi_type], values[n]) for n in group.names]
            accessor = _accessor(version, group.fmi_type)
            setter = getattr(self._slave, f"set{accessor}")
            self._fmi(
                f"{_prefix(version)}Set{accessor}", partial(setter, list(group.refs), converted)
            )

    def _get_outputs(self) -> Values:
        version = self.model_description.fmiVersion
        outputs: Values = {}
        for group in self._outputs:
            accessor = _accessor(version, group.fmi_type)
            getter = getattr(self._slave, f"get{accessor}")
            raw = self._fmi(f"{_prefix(version)}Get{accessor}", partial(getter, list(group.refs)))
            for name, value in zip(group.names, raw, strict=True):
                outputs[name] = coerce(_VALUE_TYPES[group.fmi_type], value)
        return outputs

    def _fmi(self, call: str, function: Callable[[], T]) -> T:
        """The one place FMPy's errors become ParticipantErrors."""
        try:
            return function()
        except FMICallException as exc:
            label = _STATUS[exc.status] if exc.status in range(len(_STATUS)) else str(exc.status)
            raise ParticipantError(
                f"{exc}",
                participant=self.name,
                call=call,
                status=f"{_prefix(self.model_description.fmiVersion)}{label}",
            ) from exc
        except ParticipantError:
            raise
        except Exception as exc:
            raise ParticipantError(
                f"{type(exc).__name__}: {exc}", participant=self.name, call=call
            ) from exc

    def _check_fmi1_slave(self, slave: Any) -> None:
        """FMPy neither checks fmiInstantiateSlave's result nor, in 0.3.32, fmiDoStep's status."""
        if not slave.component:
            slave.freeLibrary()
            raise ParticipantError(
                "fmiInstantiateSlave returned NULL (see the FMU's log messages for why)",
                participant=self.name,
                call="fmiInstantiateSlave",
            )
        for name in _FMI1_STATUS_FUNCTIONS:
            function = slave._functions.get(name)
            if function is not None:
                function.restype = ctypes.c_int

    def _require_instance(self, call: str) -> None:
        if self._slave is None:
            raise ParticipantError("no run: Initialize first", participant=self.name, call=call)

    async def _run(self, function: Callable[[], T]) -> T:
        if self._executor is None:
            raise ParticipantError("FMU not opened", participant=self.name, call="run")
        return await asyncio.get_running_loop().run_in_executor(self._executor, function)

    async def _free(self, *, terminate: bool = False) -> None:
        if self._slave is None or self._executor is None:
            return
        slave, self._slave = self._slave, None
        version = self.model_description.fmiVersion

        def free() -> None:
            try:
                if terminate:
                    self._fmi(f"{_prefix(version)}Terminate", slave.terminate)
            finally:
                slave.freeInstance()

        await self._run(free)


def _prefix(version: str) -> str:
    return {"1.0": "fmi", "2.0": "fmi2"}.get(version, "fmi3")
