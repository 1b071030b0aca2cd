"""The native FMU step: every in-process FMU of a run stepped by one call into C per base step.

Stepping an FMU from Python costs a ctypes call per FMI call (setters, DoStep, a getter per
type), each far dearer than the FMU's own work for a small model. The native FMU step
(``coupler_native._fmu_steps``: ``packages/coupler-native/csrc/fmu_steps.c``) runs the loop
over them in C instead: each member's inputs copied from the outputs they are
connected to, set, stepped, every output read into one array per type. The step's results row
is then read from those arrays in one call into C too (``coupler_native._rows.RowRead``), or
with one slice per array where that module is missing (``SlicedRow``: the same
``native.RowReader``, the same row).

It is used when it means exactly what the step in Python means: every member an in-process FMU
with prepared calls (``coupler.fmu.calls``: FMI 2.0/3.0 scalars), stepping every base step
(no multiples), every connection a plain copy of a numeric value (no unit or type conversion,
no strings: a string lives in its FMU's memory only until that FMU's next call). Otherwise, and
with ``--no-native-steps`` / ``COUPLER_NATIVE_STEPS=0``, the members step through Python with
the same results (``tests/test_native_kernel.py`` compares them byte for byte).

It is compiled when the coupler-native wheel is built; its structs are declared once, by
``csrc/fmu_steps.h``, and built from the plain numbers this module gives
``coupler_native._fmu_steps.Members`` (the addresses ctypes holds). Without coupler-native
installed, runs step through Python.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Mapping, Sequence
from operator import itemgetter
from typing import Any

import structlog

from coupler.channels import Value
from coupler.fmu import FmuParticipant
from coupler.fmu.calls import CONVERT, Group
from coupler_orchestrator.master.watchdog import IN_PROCESS, Armed
from coupler_orchestrator.model import Algorithm, Member, Plan
from coupler_orchestrator.native import RowReader, fmu_steps, rows

log = structlog.get_logger("coupler.kernel")

USED = "every member is an in-process FMU, every connection a plain copy"
BATCH = 512
"""Most base steps one call into C takes (``Kernel.steps``): the rows its log holds."""
OFF = "native steps are off (--no-native-steps or COUPLER_NATIVE_STEPS=0)"

library = fmu_steps
"""``library()``: the native FMU step (``coupler_native._fmu_steps``), or None (why is said
once)."""


def _address(pointer: Any) -> int:
    """The address a ctypes pointer, function or ``c_void_p`` holds."""
    return ctypes.cast(pointer, ctypes.c_void_p).value or 0


def _element(group: Group) -> Any:
    return group.buffer._type_


class _Plane:
    """One array of every output of one C type (and one conversion to Values)."""

    def __init__(self, element: Any, kind: str) -> None:
        self.element = element
        self.convert = CONVERT.get(kind)
        self.size = 0
        self.start = 0
        """Where its values begin in a row's values (``Kernel.row``)."""
        self.array: Any = None

    def allocate(self) -> None:
        self.array = (self.element * max(1, self.size))()

    def address(self, index: int) -> int:
        return ctypes.addressof(self.array) + index * ctypes.sizeof(self.element)

    def values(self) -> list[Value]:
        found = self.array[: self.size]
        return found if self.convert is None else self.convert(found)


def unsuitable(plan: Plan) -> str | None:
    """Why the native FMU step cannot step this plan (after Initialize); None when it can."""
    if not plan.order:
        return "no members"
    for m in plan.order:
        p = m.participant
        if not isinstance(p, FmuParticipant) or p.prepared() is None:
            return f"{m.name} is not an in-process FMU with prepared calls"
        if m.multiple != 1:
            return f"{m.name} steps every {m.multiple} base steps"
    for link in plan.links:
        if link.convert is not None:
            return f"{link.target}.{link.input} converts what it receives"
    return None


class Kernel:
    """The in-process FMUs of one plan, stepped in C (``unsuitable(plan)`` must be None)."""

    def __init__(self, plan: Plan, native: Any) -> None:
        self._native = native
        self._order = plan.order
        slots = {m.name: i for i, m in enumerate(plan.members)}
        planes: dict[tuple[Any, str], _Plane] = {}
        placed: list[tuple[str, Group, _Plane, int]] = []  # member, group, plane, first index
        for m in plan.order:
            calls = self._participant(m).prepared()
            assert calls is not None
            for group in calls.outputs:
                element = _element(group)
                plane = planes.setdefault((element, group.kind), _Plane(element, group.kind))
                placed.append((m.name, group, plane, plane.size))
                plane.size += group.count
        self._planes = list(planes.values())
        start = 0
        for plane in self._planes:
            plane.allocate()
            plane.start, start = start, start + plane.size
        self._slot: dict[tuple[str, str], tuple[_Plane, int, Group]] = {}
        """Every output's place: its plane, its index there and its group."""
        gets: dict[str, list[tuple[Group, _Plane, int]]] = {}
        for name, group, plane, first in placed:
            gets.setdefault(name, []).append((group, plane, first))
            for j, channel in enumerate(group.names):
                self._slot[(name, channel)] = (plane, first + j, group)
        columns = [self._slot[(m.name, c.name)] for m in plan.members for c in m.outputs]
        self.sliced = SlicedRow(
            self._planes, _row_getter([plane.start + index for plane, index, _ in columns])
        )
        """Reads the row in Python."""
        self.reader: RowReader = _reader(columns) or self.sliced
        """Reads the row: in C, when every column's type allows it; else ``sliced``."""
        self._grid = plan.grid.in_doubles()
        self._grid_time = plan.grid.time
        self._log, self._logged = self._row_log(columns, len(plan.members))
        """The log ``steps`` fills and the ``RowLog`` reading it (None: no ``steps``)."""

        feeds: dict[str, list[tuple[str, tuple[str, str]]]] = {}
        for link in plan.links:
            feeds.setdefault(link.target, []).append((link.input, (link.source, link.output)))
        self._sets: list[list[Group]] = []
        """Each member's setter groups (in stepping order), to name a failed one."""
        described = [
            self._described(m, slots[m.name], gets.get(m.name, []), feeds.get(m.name, []))
            for m in plan.order
        ]
        self.timing = (ctypes.c_double * len(plan.members))()
        watch = ctypes.c_double * 3
        self._watch = watch.from_buffer(plan.progress) if plan.progress else watch()
        self._watch[0], self._watch[1], self._watch[2] = -1.0, 0.0, 0.0
        self._stop = (ctypes.c_int * 3)()
        self._members = native.Members(
            described,
            ctypes.addressof(self.timing),
            ctypes.addressof(self._watch),
            ctypes.addressof(self._stop),
            plan.algorithm is Algorithm.JACOBI,
        )
        """The members as the C side steps them (every array it points into is this
        kernel's, or its participants')."""
        self._what = [f"{m.name}.DoStep" for m in plan.members]
        self._deadline = [m.deadline for m in plan.members]

    def _row_log(self, columns: Sequence[tuple[_Plane, int, Group]], slots: int) -> tuple[Any, Any]:
        """A ``ck_log`` of every column (freed with this kernel) and its ``RowLog``; (None, None)
        without ``coupler_native._rows``, for a column of a C type it does not read, or for a
        grid whose times doubles do not compute exactly."""
        native, codes = rows(), _codes(columns)
        if native is None or codes is None or self._grid is None:
            return None, None
        cells = [
            (plane.address(index), code)
            for (plane, index, _), code in zip(columns, codes, strict=True)
        ]
        made = self._native.Log(cells, slots, BATCH)  # MemoryError when there is none
        return made, native.RowLog(made.address, made)

    @property
    def logs(self) -> bool:
        """Whether ``steps`` can take several base steps per call."""
        return self._log is not None

    @staticmethod
    def _participant(m: Member) -> FmuParticipant:
        assert isinstance(m.participant, FmuParticipant)
        return m.participant

    @staticmethod
    def _calls(calls: Sequence[tuple[Any, Any, int, int]]) -> list[tuple[int, int, int, int]]:
        """Each call as ``ck_call`` holds it: (function, value references, count, buffer), as
        addresses."""
        return [
            (_address(function), ctypes.addressof(refs), count, buffer)
            for function, refs, count, buffer in calls
        ]

    def _described(
        self,
        m: Member,
        slot: int,
        gets: Sequence[tuple[Group, _Plane, int]],
        feed: Sequence[tuple[str, tuple[str, str]]],
    ) -> tuple[Any, ...]:
        """Member ``m`` as ``Members`` takes it (a ``ck_member``: see its docstring)."""
        participant = self._participant(m)
        calls = participant.prepared()
        assert calls is not None
        parts = calls.native
        source = dict(feed)
        sets = participant.input_groups(tuple(source)) if source else []
        copies = []
        for group in sets:
            size = ctypes.sizeof(_element(group))
            for j, name in enumerate(group.names):
                plane, index, origin = self._slot[source[name]]
                if group.kind == "String" or _element(origin) is not _element(group):
                    raise _Unsuitable(
                        f"{m.name}.{name} ({group.kind}) is fed a {origin.kind} by "
                        f"{source[name][0]}.{source[name][1]}"
                    )
                target = ctypes.addressof(group.buffer) + j * size
                copies.append((target, plane.address(index), size))
        self._sets.append(sets)
        return (
            _address(parts.instance),
            _address(parts.do_step),
            m.step,
            3 if parts.version == "3.0" else 2,
            slot,
            copies,
            self._calls([(g.function, g.refs, g.count, ctypes.addressof(g.buffer)) for g in sets]),
            self._calls(
                [(g.function, g.refs, g.count, plane.address(first)) for g, plane, first in gets]
            ),
        )

    def place(self, member: str, outputs: Mapping[str, Value]) -> None:
        """Put a member's outputs (its Initialize answer, or those it ended the run with)
        where its successors and the results row read them."""
        for channel, value in outputs.items():
            plane, index, group = self._slot[(member, channel)]
            if group.kind == "String":
                plane.array[index] = str(value).encode("utf-8")
            else:
                plane.array[index] = value

    def row(self) -> list[Value]:
        """Every member's outputs, in the results' column order."""
        return self.reader.row()

    def step(self, time: float, start: int = 0) -> tuple[int, Exception] | None:
        """Step the members from ``start`` (in stepping order) at ``time``; None when all
        stepped, else the index of the member that stopped the step and what it means (an
        error, or ``EndRun``: step on from the next member)."""
        index = self._members.step(start, time)
        if index == self._native.CK_DONE:
            return None
        return index, self._meaning(index, time)

    def steps(self, k: int, count: int, budget: float) -> tuple[int, tuple[int, Exception] | None]:
        """Base steps k, k + 1, ... in one call into C (``logs`` must be true), each logged,
        until ``count`` (at most BATCH) are done or ``budget`` seconds have passed; at least
        one is taken. Returns how many were done whole (``logged()`` tells them), and, when a
        member stopped the next one, its index and what it means, as ``step`` does (the members
        after it have not stepped: ``step(time, index + 1)`` goes on)."""
        assert self._grid is not None
        lib = self._native
        index = self._members.steps(*self._grid, k, count, budget, self._log)
        done = self._log.take()
        if index in (lib.CK_DONE, lib.CK_CLAIMED):  # claimed: the watchdog tells the rows
            return done, None
        if index == lib.CK_NO_MEMORY:
            raise MemoryError("no memory for the strings of the native FMU step's row log")
        return done, (index, self._meaning(index, self._grid_time(k + done)))

    def logged(self) -> LoggedSteps:
        """The steps the last ``steps`` call took whole."""
        return LoggedSteps(self._logged)

    def claim(self) -> LoggedSteps | None:
        """From another thread while ``steps`` is under way (a member hangs in its step): the
        steps it has taken whole so far, which its caller will then not be given (``steps``
        takes no more); None when there are none, or they were handed over already."""
        if self._log is None or self._log.claim() == 0:
            return None
        return LoggedSteps(self._logged)

    def _meaning(self, index: int, time: float) -> Exception:
        m = self._order[index]
        participant = self._participant(m)
        call, group, status = self._stop
        lib = self._native
        if call == lib.CK_CALL_TERMINATE:
            return participant.terminated(time, m.step, self._members.last(index))
        calls = participant.prepared()
        assert calls is not None
        if call == lib.CK_CALL_GET:
            name = calls.outputs[group].call
        elif call == lib.CK_CALL_SET:
            name = self._sets[index][group].call
        else:
            name = calls.native.call
        return participant.stopped(name, status, time, m.step)

    def under_way(self) -> Armed | None:
        """The member step under way for the watchdog: (what, simulated time, deadline,
        since [monotonic], cause); None between steps."""
        slot, since, time = self._watch[0], self._watch[1], self._watch[2]
        if slot < 0:
            return None
        at = int(slot)
        return self._what[at], time, self._deadline[at], since, IN_PROCESS


class LoggedSteps:
    """The base steps of one ``Kernel.steps`` call as observers read them
    (``observer.Steps``): the rows RowRead would have read after each, from the log."""

    def __init__(self, log: Any) -> None:
        self.log = log
        self.times: list[float] = log.times()

    def row(self, j: int) -> list[Value]:
        row: list[Value] = self.log.row(j)
        return row

    def seconds(self, j: int) -> list[float | None]:
        seconds: list[float | None] = self.log.seconds(j)
        return seconds

    def samples(self, member: int) -> list[float]:
        samples: list[float] = self.log.samples(member)
        return samples


class _Unsuitable(Exception):
    """A connection the native FMU step cannot copy (found while preparing it)."""


CODES = {ctypes.c_double: "d", ctypes.c_int: "i", ctypes.c_int64: "q", ctypes.c_bool: "?"}
"""The C type of an output's slot as ``RowRead`` names it (a Boolean held in an int: "b", a
String's char *: "s")."""


def _codes(columns: Sequence[tuple[_Plane, int, Group]]) -> str | None:
    """Each column's slot's C type as ``RowRead`` and ``ck_log`` name it; None for a type
    they do not read."""
    codes = []
    for plane, _, group in columns:
        code = "s" if group.kind == "String" else CODES.get(plane.element)
        if code == "i" and group.kind == "Boolean":
            code = "b"
        if code is None:
            return None
        codes.append(code)
    return "".join(codes)


def _reader(columns: Sequence[tuple[_Plane, int, Group]]) -> RowReader | None:
    """``coupler_native._rows.RowRead`` over the columns' slots; None without the module, or
    for a C type it does not read."""
    native, codes = rows(), _codes(columns)
    if native is None or codes is None:
        return None
    addresses = [plane.address(index) for plane, index, _ in columns]
    read: RowReader = native.RowRead(addresses, codes)
    return read


class SlicedRow:
    """``RowReader`` in Python: one slice per array, converted, the columns picked (the twin
    of ``coupler_native._rows.RowRead``)."""

    def __init__(
        self, planes: Sequence[_Plane], pick: Callable[[list[Value]], list[Value]]
    ) -> None:
        self._planes = planes
        self._pick = pick

    def row(self) -> list[Value]:
        values: list[Value] = []
        for plane in self._planes:
            values += plane.values()
        return self._pick(values)


def _row_getter(positions: Sequence[int]) -> Callable[[list[Value]], list[Value]]:
    if len(positions) > 1:
        pick = itemgetter(*positions)
        return lambda values: list(pick(values))
    return lambda values: [values[i] for i in positions]


def prepare(plan: Plan) -> tuple[Kernel | None, str]:
    """The kernel for this plan (after Initialize), when the plan asks for it (``native``)
    and it means exactly what the step in Python means, else None; and why (logged)."""
    if not plan.native:
        return None, OFF
    reason = unsuitable(plan)
    if reason is None:
        native = library()
        if native is None:
            return None, str(library.problem)
        try:
            kernel = Kernel(plan, native)
        except _Unsuitable as exc:
            reason = str(exc)
        else:
            log.debug("native_fmu_step", members=len(plan.order))
            return kernel, USED
    log.debug("native_fmu_step_unused", reason=reason)
    return None, reason
