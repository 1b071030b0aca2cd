"""How an FMU's variables become Coupler channels, and which FMUs Coupler refuses.

Scalars (FMI 1.0, 2.0, 3.0) are channels of their own name. A fixed-size FMI 3.0 array (a
variable with ``<Dimension>`` elements) becomes one scalar channel per element, named with
1-based indices in row-major order, the order of FMI 3.0's serialization: ``u[1]``, ``u[2]``
for a vector, ``A[1,1]``, ``A[1,2]``, ``A[2,1]`` ... for a matrix. A dimension is fixed by its
``start`` attribute, a constant, or a structural parameter's start value; such a structural
parameter keeps that value for every run (``check_parameters``).

Refused, with a ScenarioError naming the FMU and the reason: FMUs without a co-simulation
interface (model exchange or FMI 3.0 scheduled execution only), FMUs with FMI 3.0 Clock
variables (Coupler steps FMUs and never ticks clocks), and arrays whose size Coupler cannot
resolve (``unsized_array`` finds those FMPy itself cannot read, before FMPy tries).
"""

from __future__ import annotations

import itertools
import zipfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

from fmpy.model_description import ModelDescription, ScalarVariable

from coupler.channels import Causality, Channel, Value, ValueType
from coupler.errors import ScenarioError

__all__ = [
    "CAUSALITIES",
    "VALUE_TYPES",
    "ArrayInputs",
    "Exposed",
    "Layout",
    "check_supported",
    "element_names",
    "unsized_array",
]

VALUE_TYPES = {
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
"""FMI types (1.0, 2.0, 3.0) and the channel type each becomes."""

CAUSALITIES = {
    "input": Causality.INPUT,
    "output": Causality.OUTPUT,
    "parameter": Causality.PARAMETER,
    "structuralParameter": Causality.PARAMETER,
}
"""FMI causalities that become channels; the others (local, independent, ...) are not shown."""

_EMPTY: dict[ValueType, Value] = {
    ValueType.REAL: 0.0,
    ValueType.INTEGER: 0,
    ValueType.ENUMERATION: 0,
    ValueType.BOOLEAN: False,
    ValueType.STRING: "",
    ValueType.BINARY: b"",
}


def check_supported(md: ModelDescription, path: Path) -> None:
    """Refuse an FMU Coupler cannot drive: no co-simulation interface, or FMI 3.0 clocks."""
    if md.coSimulation is None:
        if getattr(md, "scheduledExecution", None) is not None:
            raise ScenarioError(
                f"{path}: FMU '{md.modelName}' implements FMI 3.0 Scheduled Execution only; "
                f"Coupler runs co-simulation FMUs (export it with a <CoSimulation> interface)"
            )
        raise ScenarioError(
            f"{path}: FMU '{md.modelName}' has no co-simulation interface "
            f"(Coupler runs co-simulation FMUs; export it for co-simulation)"
        )
    clocks = [v for v in md.modelVariables if v.type == "Clock"]
    if clocks:
        names = ", ".join(f"'{v.name}' ({v.causality})" for v in clocks)
        raise ScenarioError(
            f"{path}: FMU '{md.modelName}' has FMI 3.0 Clock variable(s) {names}; Coupler steps "
            f"FMUs on its time grid and does not tick clocks (event mode, scheduled execution): "
            f"use a variant of the FMU without clocks"
        )


def element_names(name: str, shape: tuple[int, ...]) -> tuple[str, ...]:
    """The channel names of a variable: ``(name,)`` for a scalar, else 1-based row-major."""
    if not shape:
        return (name,)
    indices = itertools.product(*(range(1, n + 1) for n in shape))
    return tuple(f"{name}[{','.join(map(str, index))}]" for index in indices)


@dataclass(frozen=True)
class Exposed:
    """One FMI variable as channels: ``names`` has one name, or one per array element."""

    variable: ScalarVariable
    names: tuple[str, ...]
    starts: tuple[Value | None, ...]
    is_array: bool
    max_bytes: int = 0
    """FMI 3 ``Binary``: its ``maxSize``, the largest value (0: none given)."""

    @property
    def type(self) -> ValueType:
        return VALUE_TYPES[self.variable.type]

    def channels(self) -> list[Channel]:
        v = self.variable
        unit = v.unit or (v.declaredType.unit if v.declaredType else None) or ""
        return [
            Channel(
                name=name,
                causality=CAUSALITIES[v.causality],
                type=self.type,
                unit=unit,
                start=start,
                description=v.description or "",
                max_bytes=self.max_bytes,
            )
            for name, start in zip(self.names, self.starts, strict=True)
        ]


@dataclass(frozen=True)
class Layout:
    """The FMU's channels: every exposed variable in model-description order.

    ``fixed`` maps each structural parameter that sizes an array to the value it was sized
    with (its start value) and the arrays it sizes.
    """

    exposed: tuple[Exposed, ...]
    fixed: Mapping[str, tuple[int, tuple[str, ...]]]

    @classmethod
    def of(cls, md: ModelDescription, path: Path) -> Layout:
        exposed: list[Exposed] = []
        fixed: dict[str, tuple[int, list[str]]] = {}
        sizes = binary_sizes(path) if any(v.type == "Binary" for v in md.modelVariables) else {}
        for v in md.modelVariables:
            if v.causality not in CAUSALITIES or v.type not in VALUE_TYPES:
                continue
            shape = _shape(v, md, path, fixed)
            names = element_names(v.name, shape)
            if names:
                starts = _starts(v, len(names), bool(shape), path)
                exposed.append(Exposed(v, names, starts, bool(shape), sizes.get(v.name, 0)))
        return cls(
            exposed=tuple(exposed),
            fixed={name: (size, tuple(arrays)) for name, (size, arrays) in fixed.items()},
        )

    def channels(self) -> tuple[Channel, ...]:
        return tuple(c for e in self.exposed for c in e.channels())

    def variables(self) -> dict[str, ScalarVariable]:
        """Channel name -> its FMI variable (the array for an element)."""
        return {name: e.variable for e in self.exposed for name in e.names}

    def element_index(self) -> dict[str, int]:
        """Channel name of each array element -> its position in the array's values."""
        return {name: i for e in self.exposed if e.is_array for i, name in enumerate(e.names)}

    def arrays(self, *causalities: str) -> list[Exposed]:
        return [e for e in self.exposed if e.is_array and e.variable.causality in causalities]

    def check_parameters(self, parameters: Mapping[str, Value], fmu: str) -> None:
        """Refuse a value for a structural parameter other than the one its arrays have."""
        for name, (size, arrays) in self.fixed.items():
            if name in parameters and parameters[name] != size:
                raise ScenarioError(
                    f"FMU '{fmu}': structural parameter '{name}' sizes the array(s) "
                    f"{', '.join(arrays)}, whose channels Coupler made with {name} = {size} "
                    f"(its start value); it cannot be set to {parameters[name]!r} for a run"
                )


class ArrayInputs:
    """Current values of an FMU's array inputs and parameters.

    FMI 3.0 sets an array whole; ``complete`` adds the elements a call does not give, with their
    last value (initially the start value), so every array in the result is complete and in
    row-major order.
    """

    def __init__(self, arrays: Iterable[Exposed]) -> None:
        self._arrays = list(arrays)
        self._array_of = {name: e for e in self._arrays for name in e.names}
        self._current: dict[str, list[Value]] = {}
        self.reset()

    def reset(self) -> None:
        """Back to the start values, for a new run."""
        self._current = {
            e.variable.name: [_EMPTY[e.type] if s is None else s for s in e.starts]
            for e in self._arrays
        }

    def complete(self, values: Mapping[str, Value]) -> Mapping[str, Value]:
        touched = {self._array_of[n].variable.name for n in values if n in self._array_of}
        if not touched:
            return values
        out = {n: v for n, v in values.items() if n not in self._array_of}
        for array in self._arrays:
            if array.variable.name not in touched:
                continue
            current = self._current[array.variable.name]
            for i, name in enumerate(array.names):
                if name in values:
                    current[i] = values[name]
                out[name] = current[i]
        return out


def _shape(
    v: ScalarVariable,
    md: ModelDescription,
    path: Path,
    fixed: dict[str, tuple[int, list[str]]],
) -> tuple[int, ...]:
    """The array's size, checked: every dimension a number, a constant or a structural param."""
    shape: list[int] = []
    for dimension in getattr(v, "dimensions", ()):
        if dimension.start is not None:
            shape.append(int(dimension.start))
            continue
        sizer = dimension.variable
        if (
            sizer is None
            or sizer.type != "UInt64"
            or sizer.start is None
            or not (sizer.causality == "structuralParameter" or sizer.variability == "constant")
        ):
            what = f"'{sizer.name}'" if sizer is not None else "no variable"
            raise ScenarioError(
                f"{path}: FMU '{md.modelName}': the size of array '{v.name}' is given by "
                f"value reference {dimension.valueReference} ({what}), which is not a UInt64 "
                f"constant or structural parameter with a start value; Coupler cannot size "
                f"the array's channels"
            )
        size = int(sizer.start)
        shape.append(size)
        if sizer.causality == "structuralParameter":
            arrays = fixed.setdefault(sizer.name, (size, []))[1]
            if v.name not in arrays:
                arrays.append(v.name)
    return tuple(shape)


def _starts(v: ScalarVariable, count: int, array: bool, path: Path) -> tuple[Value | None, ...]:
    if v.start is None:
        return (None,) * count
    if not array:
        return (_parse(v.type, v.start),)
    texts = str(v.start).split()
    if len(texts) == 1:
        texts *= count
    if len(texts) != count:
        raise ScenarioError(
            f"{path}: array '{v.name}' has {len(texts)} start values for {count} elements; "
            f"give one value per element (row-major) or one for all"
        )
    return tuple(_parse(v.type, text) for text in texts)


def _parse(fmi_type: str, text: str) -> Value:
    value_type = VALUE_TYPES[fmi_type]
    if value_type is ValueType.REAL:
        return float(text)
    if value_type in (ValueType.INTEGER, ValueType.ENUMERATION):
        return int(text)
    if value_type is ValueType.BOOLEAN:
        return text.strip().lower() in ("true", "1")
    if value_type is ValueType.BINARY:
        return bytes.fromhex(text)
    return text


def binary_sizes(path: Path) -> dict[str, int]:
    """The ``maxSize`` of the FMU's ``Binary`` variables that give one (FMI 3), by name: what
    their channels declare as their largest value. FMPy does not read the attribute."""
    try:
        with zipfile.ZipFile(path) as fmu:
            text = fmu.read("modelDescription.xml")
        if b"maxSize" not in text:
            return {}
        root = ElementTree.fromstring(text)
    except (OSError, KeyError, zipfile.BadZipFile, ElementTree.ParseError):
        return {}
    variables = root.find("ModelVariables")
    sizes = {}
    for v in variables if variables is not None else ():
        size = v.get("maxSize", "")
        if v.tag == "Binary" and size.isdigit() and v.get("name"):
            sizes[str(v.get("name"))] = int(size)
    return sizes


def unsized_array(path: Path) -> str | None:
    """Why an array of the FMU has no size, else None (also for FMUs that are not readable).

    FMPy sizes every array while reading and fails (leaving the FMU's file open) on a
    ``<Dimension>`` whose value reference names no variable or a variable without a start
    value: this is checked first. Model descriptions without arrays are not parsed here.
    """
    try:
        with zipfile.ZipFile(path) as fmu:
            text = fmu.read("modelDescription.xml")
        if b"<Dimension" not in text:
            return None
        root = ElementTree.fromstring(text)
    except (OSError, KeyError, zipfile.BadZipFile, ElementTree.ParseError):
        return None
    variables = root.find("ModelVariables")
    if variables is None:
        return None
    by_ref = {v.get("valueReference"): v for v in variables}
    for v in variables:
        for dimension in v.findall("Dimension"):
            if dimension.get("start") is not None:
                continue
            ref = dimension.get("valueReference")
            sizer = by_ref.get(ref)
            if sizer is None:
                return (
                    f"the size of array '{v.get('name')}' is given by value reference {ref}, "
                    f"which no variable has"
                )
            if sizer.get("start") is None:
                return (
                    f"the size of array '{v.get('name')}' is given by '{sizer.get('name')}' "
                    f"(value reference {ref}), which has no start value, so Coupler cannot "
                    f"size the array's channels; give '{sizer.get('name')}' a start value"
                )
    return None
