"""FMI calls prepared once per FMU instance, for the step loop.

FMPy's getters and setters build ctypes arrays and Python lists on every call; here the value
references and value buffers of each group of variables are ctypes arrays made once, and the
C functions of the FMU's shared library are called directly (FMPy loads them and sets their
argument types; its status checks are redone here). A step then sets its inputs, steps and reads
its outputs without allocating anything but the outputs' Python values.

Prepared: FMI 2.0 Real/Integer/Boolean/Enumeration/String and FMI 3.0
Float64/Int32/Int64/Boolean/String scalars (strings as arrays of char pointers, decoded as
UTF-8). Anything else (binaries, the narrower FMI 3.0 integer types, arrays, FMI 1.0) leaves
``prepare`` returning None and the FMU stepping through FMPy's own calls (``coupler.fmu``).
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from coupler.channels import Value

#: FMI type -> (ctypes element type, FMPy function suffix), per FMI version.
_FAST: dict[str, dict[str, tuple[Any, str]]] = {
    "2.0": {
        "Real": (ctypes.c_double, "Real"),
        "Integer": (ctypes.c_int, "Integer"),
        "Enumeration": (ctypes.c_int, "Integer"),
        "Boolean": (ctypes.c_int, "Boolean"),
        "String": (ctypes.c_char_p, "String"),
    },
    "3.0": {
        "Float64": (ctypes.c_double, "Float64"),
        "Int32": (ctypes.c_int32, "Int32"),
        "Int64": (ctypes.c_int64, "Int64"),
        "Enumeration": (ctypes.c_int64, "Int64"),
        "Boolean": (ctypes.c_bool, "Boolean"),
        "String": (ctypes.c_char_p, "String"),
    },
}
_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")


class CallFailed(Exception):
    """A prepared FMI call returned a status worse than Warning."""

    def __init__(self, call: str, status: int) -> None:
        super().__init__(f"{call} returned {status_name(status)}")
        self.call = call
        self.status = status


def status_name(status: int) -> str:
    return _STATUS[status] if 0 <= status < len(_STATUS) else str(status)


@dataclass(frozen=True)
class Group:
    """Variables of one FMI type: their references, a buffer and the function to call."""

    names: tuple[str, ...]
    function: Any
    refs: Any
    count: int
    buffer: Any
    call: str
    kind: str
    """The FMI type: Boolean values become bool, String values str."""


@dataclass(frozen=True)
class NativeParts:
    """An instance's handle, FMI version, DoStep function and its name, for a caller in C."""

    instance: Any
    version: str
    do_step: Any
    call: str


CONVERT: dict[str, Callable[[Any], list[Value]]] = {
    "Boolean": lambda buffer: list(map(bool, buffer)),
    "String": lambda buffer: [v.decode("utf-8", "replace") if v else "" for v in buffer],
}
"""FMI type -> its buffer's values as Values, for the types whose ctypes values are not."""


class Calls:
    """The prepared calls of one FMU instance."""

    def __init__(
        self, slave: Any, version: str, outputs: list[Group], setters: dict[str, tuple[Any, Any]]
    ) -> None:
        self._component = slave.component
        self._version = version
        self.outputs = tuple(outputs)
        """The output groups, in the order ``get`` reads them."""
        arity = 5 if version == "3.0" else 4  # FMI 3.0 getters also take the number of values
        self._getters = [
            (
                g.function,
                (self._component, g.refs, g.count, g.buffer, g.count)[:arity],
                g.buffer,
                CONVERT.get(g.kind),
                g.call,
            )
            for g in outputs
        ]
        """Per output group: its getter, the getter's arguments, the buffer it fills, what
        turns the buffer's values into Values (None: they are already) and its name."""
        self._output_names = tuple(name for g in outputs for name in g.names)
        self._setters = setters
        """FMI type -> (setter function, ctypes element type)."""
        self._input_groups: dict[tuple[str, ...], list[Group]] = {}
        functions = slave._functions
        prefix = "fmi2" if version == "2.0" else "fmi3"
        self._do_step = functions[f"{prefix}DoStep"]
        self.native = NativeParts(slave.component, version, self._do_step, f"{prefix}DoStep")
        """What a step loop in C needs besides the groups (the orchestrator's native FMU step)."""
        self._prefix = prefix
        if version == "3.0":
            self._event = ctypes.c_bool()
            self._terminate = ctypes.c_bool()
            self._early = ctypes.c_bool()
            self._last = ctypes.c_double()
            self._step_args = (
                ctypes.byref(self._event),
                ctypes.byref(self._terminate),
                ctypes.byref(self._early),
                ctypes.byref(self._last),
            )

    def setters_for(
        self, names: tuple[str, ...], types: Mapping[str, tuple[str, int]]
    ) -> list[Group]:
        """Setter groups for a set of input names (the step loop asks for the same set)."""
        groups = self._input_groups.get(names)
        if groups is None:
            by_type: dict[str, list[str]] = {}
            for name in names:
                by_type.setdefault(types[name][0], []).append(name)
            groups = []
            for fmi_type, members in by_type.items():
                function, element = self._setters[fmi_type]
                refs = (ctypes.c_uint * len(members))(*(types[n][1] for n in members))
                groups.append(
                    Group(
                        tuple(members),
                        function,
                        refs,
                        len(members),
                        (element * len(members))(),
                        f"{self._prefix}Set{_FAST[self._version][fmi_type][1]}",
                        fmi_type,
                    )
                )
            self._input_groups[names] = groups
        return groups

    def set(self, groups: Sequence[Group], values: Mapping[str, Value]) -> None:
        component = self._component
        for group in groups:
            buffer = group.buffer
            if group.kind == "String":
                for i, name in enumerate(group.names):
                    buffer[i] = str(values[name]).encode("utf-8")
            else:
                for i, name in enumerate(group.names):
                    buffer[i] = values[name]
            if self._version == "2.0":
                status = group.function(component, group.refs, group.count, buffer)
            else:
                status = group.function(component, group.refs, group.count, buffer, group.count)
            if status > 1:
                raise CallFailed(group.call, status)

    def do_step(self, time: float, step: float) -> tuple[bool, float]:
        """Step; (the FMU asks to terminate, the last time it reached) — FMI 3.0 only; an FMI
        2.0 discard is a CallFailed with status 2, for ``coupler.fmu`` to look into."""
        if self._version == "2.0":
            status = self._do_step(self._component, time, step, 1)
            if status > 1:
                raise CallFailed("fmi2DoStep", status)
            return False, time + step
        status = self._do_step(self._component, time, step, True, *self._step_args)
        if status > 1:
            raise CallFailed("fmi3DoStep", status)
        return self._terminate.value, self._last.value

    def get(self) -> dict[str, Value]:
        values: list[Value] = []
        for function, arguments, buffer, convert, call in self._getters:
            status = function(*arguments)
            if status > 1:
                raise CallFailed(call, status)
            values += buffer if convert is None else convert(buffer)
        return dict(zip(self._output_names, values, strict=True))


def prepare(
    slave: Any,
    version: str,
    outputs: Sequence[tuple[str, str, int]],
    inputs: Sequence[tuple[str, str, int]],
) -> Calls | None:
    """Prepared calls for an instance, or None when any variable needs FMPy's own calls.

    ``outputs`` and ``inputs`` are (channel name, FMI type, value reference) of every output
    and of every input or parameter that may be set while stepping.
    """
    fast = _FAST.get(version)
    functions = getattr(slave, "_functions", None)
    if fast is None or not isinstance(functions, dict):
        return None
    if any(t not in fast for _, t, _ in (*outputs, *inputs)):
        return None
    prefix = "fmi2" if version == "2.0" else "fmi3"
    needed = [f"{prefix}DoStep"] + [f"{prefix}Get{fast[t][1]}" for _, t, _ in outputs]
    needed += [f"{prefix}Set{fast[t][1]}" for _, t, _ in inputs]
    if any(name not in functions for name in needed):
        return None
    by_type: dict[str, list[tuple[str, int]]] = {}
    for name, fmi_type, ref in outputs:
        by_type.setdefault(fmi_type, []).append((name, ref))
    groups = []
    for fmi_type, members in by_type.items():
        element, suffix = fast[fmi_type]
        groups.append(
            Group(
                tuple(n for n, _ in members),
                functions[f"{prefix}Get{suffix}"],
                (ctypes.c_uint * len(members))(*(r for _, r in members)),
                len(members),
                (element * len(members))(),
                f"{prefix}Get{suffix}",
                fmi_type,
            )
        )
    setters = {
        t: (functions[f"{prefix}Set{fast[t][1]}"], fast[t][0]) for t in {t for _, t, _ in inputs}
    }
    return Calls(slave, version, groups, setters)
