"""``FmuParticipant``: an FMU (FMI 1.0, 2.0 or 3.0 co-simulation) run in-process through FMPy.

Steps run on the caller's thread, through FMI calls prepared once per instance
(``coupler.fmu.calls``): no thread hop, no per-call allocation. What is slow and rare — reading
and unpacking the FMU, instantiating and initializing it, terminating and freeing it — runs in
a daemon thread off the event loop, so a caller's deadline can give up on an FMU that hangs
there (the FMU is then left alone: "wedged"), and a hung FMU never keeps the process from
exiting. A step that hangs blocks its thread; the orchestrator's watchdog deals with that.
A failing FMI call becomes a ``ParticipantError`` carrying the FMU, the call and the FMI status
(``_fmi`` and ``_failed``, the places FMPy's and the prepared calls' errors are translated).
Which variables are channels (FMI 3.0 arrays as one channel per element) and which FMUs are
refused is ``coupler.fmu.channels``' concern.
"""

from __future__ import annotations

import asyncio
import ctypes
import threading
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, TypeVar

import fmpy
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2LastSuccessfulTime, fmi2Terminated
from fmpy.model_description import ModelDescription, ScalarVariable

from coupler.archives import Budget, extract, remove_scratch, scratch_folder
from coupler.channels import Capabilities, Description, RunSetup, Value
from coupler.errors import ParticipantError, ScenarioError, ValueTooLarge
from coupler.fmu.calls import CallFailed, Calls, Group, prepare, status_name
from coupler.fmu.channels import (
    VALUE_TYPES,
    ArrayInputs,
    Layout,
    check_supported,
    unsized_array,
)
from coupler.participant import EndRun, Participant, Values
from coupler.values import coerce

T = TypeVar("T")

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


#: Times closer than this (relative) are the same time reached.
_TIME_TOLERANCE = 1e-9


@dataclass(frozen=True)
class _Group:
    """Variables of one FMI type, read or written with one call.

    ``count`` is the number of values when arrays make it differ from the number of refs
    (FMI 3.0 only), else None.
    """

    fmi_type: str
    names: tuple[str, ...]
    refs: tuple[int, ...]
    count: int | None = None


def _accessor(fmi_version: str, fmi_type: str) -> str:
    """Name of the FMPy getter/setter suffix for an FMI type."""
    if fmi_version == "3.0":
        return "Int64" if fmi_type == "Enumeration" else fmi_type
    return "Integer" if fmi_type == "Enumeration" else fmi_type


class FmuParticipant(Participant):
    """An FMU as a participant. ``path`` is the .fmu file; ``name`` defaults to its model name.

    The FMU is unpacked within ``budget`` into a scratch folder removed on ``close`` (and by
    ``coupler.archives.remove_all_scratch``); given ``unpacked``, a folder where its owner
    unpacked it already (the generic FMU host's parent), that folder is used and left alone.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        name: str | None = None,
        budget: Budget | None = None,
        unpacked: Path | None = None,
    ) -> None:
        self.path = Path(path)
        self._name = name
        self._budget = budget
        self._given = unpacked
        self._md: ModelDescription | None = None
        self._unzipdir: str | None = None
        self._slave: Any = None
        self._calls: Calls | None = None
        self._input_types: dict[str, tuple[str, int]] = {}
        self._wedged: str | None = None
        """The call the FMU hangs in, once a caller gave up on it: never call it again."""
        self._layout = Layout(exposed=(), fixed={})
        self._variables: dict[str, ScalarVariable] = {}
        self._elements: dict[str, int] = {}
        self._arrays: ArrayInputs | None = None
        self._outputs: list[_Group] = []
        self._maxima: dict[str, int] = {}
        """The Binary inputs and parameters that declare a ``maxSize``, and it (FMI 3)."""
        self._group_cache: dict[tuple[str, ...], list[_Group]] = {}

    @property
    def name(self) -> str:
        return self._name or (self._md.modelName if self._md else self.path.stem)

    async def open(self) -> None:
        """Read and unpack the FMU, off the event loop."""
        if self._md is None:
            await asyncio.to_thread(self._open)

    def _open(self) -> None:
        if self._md is not None:
            return
        if not self.path.is_file():
            raise ScenarioError(f"FMU not found: {self.path} (check the component's source)")
        unsized = unsized_array(self.path)
        if unsized is not None:
            raise ScenarioError(f"{self.path}: {unsized}")
        try:
            md = fmpy.read_model_description(str(self.path), validate=False)
        except Exception as exc:
            raise ScenarioError(f"{self.path}: not a readable FMU: {exc}") from exc
        check_supported(md, self.path)
        self._layout = Layout.of(md, self.path)
        if self._given is None:
            self._unzipdir = str(unpack(self.path, self._budget))
        else:
            self._unzipdir = str(self._given)
        self._md = md
        self._variables = self._layout.variables()
        self._maxima = {
            name: e.max_bytes
            for e in self._layout.exposed
            if e.max_bytes > 0 and e.variable.causality != "output"
            for name in e.names
        }
        self._elements = self._layout.element_index()
        settable = self._layout.arrays("input", "parameter", "structuralParameter")
        self._arrays = ArrayInputs(settable) if settable else None
        self._outputs = self._groups(
            name for name, v in self._variables.items() if v.causality == "output"
        )

    async def close(self) -> None:
        try:
            await self._free()
        finally:
            if self._unzipdir is not None and self._given is None:
                remove_scratch(Path(self._unzipdir))
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
            channels=self._layout.channels(),
        )

    async def initialize(self, setup: RunSetup) -> Values:
        await self.open()
        await self._free()
        md = self.model_description
        version = md.fmiVersion
        start, stop = setup.start_time, setup.stop_time
        if self._layout.fixed:
            self._layout.check_parameters(setup.parameters, self.name)
        if self._arrays is not None:
            self._arrays.reset()

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
            self._prepare(version)
            return self._get_outputs()

        return await self._run("Initialize", init)

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return self.step_now(time, step, inputs)

    def step_now(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        """One step, on this thread: set the inputs, step, read the outputs (``do_step``
        without awaiting: a master in this process may call it directly)."""
        calls = self._calls
        if calls is None:
            return self._step_through_fmpy(time, step, inputs)
        try:
            if inputs:
                names = tuple(inputs)
                if names not in self._checked_inputs:
                    self._check_inputs(names)
                calls.set(calls.setters_for(names, self._input_types), inputs)
            terminate, reached = calls.do_step(time, step)
            if terminate:
                raise self._fmi3_terminated(time, step, reached)
            return calls.get()
        except CallFailed as exc:
            raise self._failed(exc, time, step) from exc

    # --- for a step loop in C (the orchestrator's native FMU step), after Initialize -----------

    def prepared(self) -> Calls | None:
        """The instance's prepared calls; None when it steps through FMPy's own."""
        return self._calls

    def input_groups(self, names: tuple[str, ...]) -> list[Group]:
        """The prepared setter groups of these inputs (ScenarioError for one it lacks)."""
        assert self._calls is not None
        if names not in self._checked_inputs:
            self._check_inputs(names)
        return self._calls.setters_for(names, self._input_types)

    def stopped(self, call: str, status: int, time: float, step: float) -> Exception:
        """What a prepared call that stopped a step means: the participant's error, or its
        request to end the run (fmi2Discard with fmi2Terminated)."""
        return self._failed(CallFailed(call, status), time, step)

    def terminated(self, time: float, step: float, reached: float) -> EndRun:
        """fmi3DoStep set terminateSimulation, having reached ``reached``."""
        return self._fmi3_terminated(time, step, reached)

    def _step_through_fmpy(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        """A step through FMPy's calls: FMI 1.0, arrays, strings and the rarer types."""
        version = self.model_description.fmiVersion
        self._require_instance("DoStep")
        self._set(inputs)
        try:
            result = self._fmi(
                f"{_prefix(version)}DoStep",
                lambda: self._slave.doStep(
                    currentCommunicationPoint=time, communicationStepSize=step
                ),
            )
        except ParticipantError as exc:
            if exc.status == "fmi2Discard":
                raise self._fmi2_discarded(time, step, exc) from exc
            raise
        if version == "3.0" and result[1]:
            raise self._fmi3_terminated(time, step, result[3])
        return self._get_outputs()

    async def terminate(self, reason: str = "") -> None:
        await self._free(terminate=True)

    def _prepare(self, version: str) -> None:
        """The prepared calls of the new instance, when every variable allows them."""
        self._calls = None
        self._checked_inputs: set[tuple[str, ...]] = set()
        if self._elements or self._arrays is not None:
            return  # arrays keep FMPy's calls (coupler.fmu.channels completes them)
        variables = self._variables
        outputs = [
            (n, v.type, v.valueReference) for n, v in variables.items() if v.causality == "output"
        ]
        inputs = [
            (n, v.type, v.valueReference) for n, v in variables.items() if v.causality == "input"
        ]
        self._input_types = {n: (t, r) for n, t, r in inputs}
        self._calls = prepare(self._slave, version, outputs, inputs)

    def _check_inputs(self, names: tuple[str, ...]) -> None:
        unknown = [n for n in names if n not in self._input_types]
        if unknown:
            raise ScenarioError(f"FMU '{self.name}' has no input {', '.join(map(repr, unknown))}")
        self._checked_inputs.add(names)

    def _failed(self, failed: CallFailed, time: float, step: float) -> Exception:
        """A prepared call's failure as the participant's error (or its request to end)."""
        version = self.model_description.fmiVersion
        error = ParticipantError(
            f"{failed.call} returned {status_name(failed.status)}",
            participant=self.name,
            call=failed.call,
            status=f"{_prefix(version)}{status_name(failed.status)}",
        )
        if failed.call == "fmi2DoStep" and failed.status == 2:
            return self._fmi2_discarded(time, step, error)
        return error

    # --- an FMU ending the run, run on the worker thread -------------------------------------

    def _fmi2_discarded(self, time: float, step: float, discard: ParticipantError) -> Exception:
        """fmi2DoStep returned fmi2Discard: EndRun if the FMU asks to terminate, else the error."""
        try:
            terminated = self._fmi(
                "fmi2GetBooleanStatus", lambda: self._slave.getBooleanStatus(fmi2Terminated)
            )
        except ParticipantError:
            return discard  # no answer: a step that failed
        if not terminated:
            return discard
        reached = self._fmi(
            "fmi2GetRealStatus", lambda: self._slave.getRealStatus(fmi2LastSuccessfulTime)
        )
        return EndRun(
            _termination("fmi2DoStep returned fmi2Discard, fmi2Terminated", reached, time, step),
            self._get_outputs(),
        )

    def _fmi3_terminated(self, time: float, step: float, last_successful_time: float) -> EndRun:
        """fmi3DoStep set terminateSimulation: EndRun with the outputs at the time reached."""
        return EndRun(
            _termination("fmi3DoStep set terminateSimulation", last_successful_time, time, step),
            self._get_outputs(),
        )

    # --- FMI plumbing, run on the worker thread ----------------------------------------------

    def _groups(self, names: Iterable[str]) -> list[_Group]:
        """One group per FMI type; an array's elements (complete, in order) share its ref."""
        by_type: dict[str, list[str]] = {}
        for name in names:
            by_type.setdefault(self._variables[name].type, []).append(name)
        groups = []
        for fmi_type, members in by_type.items():
            refs = tuple(
                self._variables[n].valueReference for n in members if self._elements.get(n, 0) == 0
            )
            count = len(members) if len(refs) != len(members) else None
            groups.append(_Group(fmi_type, tuple(members), refs, count))
        return groups

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
        if self._maxima:
            self._check_sizes(values)
        if self._arrays is not None:
            values = self._arrays.complete(values)
        version = self.model_description.fmiVersion
        for group in self._input_groups(tuple(values)):
            converted = [coerce(VALUE_TYPES[group.fmi_type], values[n]) for n in group.names]
            accessor = _accessor(version, group.fmi_type)
            setter = getattr(self._slave, f"set{accessor}")
            self._fmi(
                f"{_prefix(version)}Set{accessor}", partial(setter, list(group.refs), converted)
            )

    def _check_sizes(self, values: Mapping[str, Value]) -> None:
        """RESOURCE_EXHAUSTED naming the channel when a Binary value is over its ``maxSize``:
        the FMU was promised at most that many bytes. (Served, the participant runtime checks
        inputs as they arrive; in the orchestrator's process nothing else does.)"""
        for name, maximum in self._maxima.items():
            value = values.get(name)
            if isinstance(value, bytes | bytearray) and len(value) > maximum:
                kind = "parameter" if self._variables[name].causality == "parameter" else "input"
                exc = ValueTooLarge(channel=name, kind=kind, size=len(value), maximum=maximum)
                raise ParticipantError(
                    exc.naming(self.name),
                    participant=self.name,
                    call="fmi3SetBinary",
                    status="RESOURCE_EXHAUSTED",
                )

    def _get_outputs(self) -> Values:
        version = self.model_description.fmiVersion
        outputs: Values = {}
        for group in self._outputs:
            accessor = _accessor(version, group.fmi_type)
            getter = getattr(self._slave, f"get{accessor}")
            if group.count is None:
                call = partial(getter, list(group.refs))
            else:
                call = partial(getter, list(group.refs), group.count)
            raw = self._fmi(f"{_prefix(version)}Get{accessor}", call)
            for name, value in zip(group.names, raw, strict=True):
                outputs[name] = coerce(VALUE_TYPES[group.fmi_type], value)
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

    async def _run(self, call: str, function: Callable[[], T]) -> T:
        """``function`` in a daemon thread; if the caller gives up (a deadline, an interrupt)
        while it runs, the FMU is wedged in ``call`` and never called again."""
        if self._wedged is not None:
            raise ParticipantError(
                f"the FMU did not return from {self._wedged} and is left alone",
                participant=self.name,
                call=call,
            )
        try:
            return await in_daemon_thread(function, name=f"fmu-{self.name}")
        except asyncio.CancelledError:
            self._wedged = call
            raise

    async def _free(self, *, terminate: bool = False) -> None:
        if self._slave is None:
            return
        slave, self._slave, self._calls = self._slave, None, None
        if self._wedged is not None:
            return  # an instance hung in a call is never called again; the process ends it
        version = self.model_description.fmiVersion

        def free() -> None:
            try:
                if terminate:
                    self._fmi(f"{_prefix(version)}Terminate", slave.terminate)
            finally:
                slave.freeInstance()

        await self._run("Terminate" if terminate else "FreeInstance", free)


def unpack(fmu: Path, budget: Budget | None = None) -> Path:
    """``fmu`` unpacked within ``budget`` into a new scratch folder (removed again if that
    fails); the caller removes it (``coupler.archives.remove_scratch``)."""
    folder = scratch_folder("coupler-fmu-")
    try:
        extract(fmu, folder, budget=budget)
    except BaseException:
        remove_scratch(folder)
        raise
    return folder


async def in_daemon_thread(function: Callable[[], T], *, name: str) -> T:
    """``function()`` in a new daemon thread, awaited: a call that never returns neither blocks
    the event loop nor keeps the process from exiting (a thread pool's workers would)."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[T] = loop.create_future()

    def settle(outcome: Callable[[], None]) -> None:
        if not future.done():
            outcome()

    def run() -> None:
        try:
            result = function()
        except BaseException as exc:  # delivered to the awaiting coroutine
            error = exc
            loop.call_soon_threadsafe(settle, lambda: future.set_exception(error))
        else:
            loop.call_soon_threadsafe(settle, lambda: future.set_result(result))

    threading.Thread(target=run, name=name, daemon=True).start()
    return await future


def _termination(how: str, reached: float, time: float, step: float) -> str:
    """The reason of an FMU's request to end the run; says so when it stopped inside the step
    (a last successful time before the step's end; one outside the step is not believed)."""
    end = time + step
    reason = f"the FMU requested to terminate the simulation ({how})"
    tolerance = _TIME_TOLERANCE * max(1.0, abs(end))
    if time - tolerance <= reached < end - tolerance:
        reason += (
            f"; it stopped at t={reached:g} s, before the step's end t={end:g} s, so the row "
            f"at t={end:g} s holds its outputs at t={reached:g} s"
        )
    return reason


def _prefix(version: str) -> str:
    return {"1.0": "fmi", "2.0": "fmi2"}.get(version, "fmi3")
