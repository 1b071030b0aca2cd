"""OpenMCx's dialect of SSP (eclipse/openmcx, its schemas in ``scripts/SSP``): ports, vector
connectors and their slices, built-in components, inter/extrapolation, and whether a scenario
runs with OpenMCx's semantics.

- Connector, ``com.avl.model.connect.ssp.port``: ``<Port nameInModel id>`` with one of
  ``<Real|Integer min max scale offset default initial writeResults/>``, ``<Boolean|String
  default initial writeResults/>``, ``<Binary/>``, ``<BinaryReference/>`` or ``<RealVector|
  IntegerVector startIndex endIndex .../>`` whose other attributes are space-separated lists, one
  entry per element. A vector connector ``v`` becomes one connector per element, ``v[s]`` ..
  ``v[e]``, bound to the participant's ``v[i]`` (or ``nameInModel[i]``).
- Connection, ``com.avl.model.connect.ssp.connection``: ``<Connection><Start startIndex
  endIndex/><End startIndex endIndex/></Connection>``: element i of the start range drives
  element i of the end range; a side without indices is a scalar connector.
- Connection, ``com.avl.model.connect.ssp.connection.inter_extrapolation``:
  ``<InterExtrapolation extrapolationOrder interpolationOrder extrapolationInterval
  interpolationInterval/>`` (orders ``zero``/``first``).
- Component, ``com.avl.model.connect.ssp.component.constant`` / ``.integrator`` /
  ``.vector_integrator``: ``<SpecificData>`` of the built-ins ``application/avl-mcx-constant``
  (one ``Real|Integer|String|Boolean value`` or ``RealVector|IntegerVector value="a b c"`` per
  output connector, in order), ``-integrator`` (``gain numSubSteps initialState``) and
  ``-vector-integrator`` (``initialState``).

What a port does to the values through it (``port_input``, ``port_output``) is here too: inputs
``x * scale + offset``, then clamped to [min, max]; outputs clamped first.

Every attribute is checked against OpenMCx's schema: an unknown one, a missing required one or a
value that does not fit is an error naming the file and line.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import replace

from coupler.channels import Value, ValueType
from coupler.errors import ScenarioError

from .documents import Element, boolean, checkpoint, elements, integer, local, number, where
from .model import (
    CONSTANT_TYPE,
    INTEGRATOR_TYPE,
    VECTOR_INTEGRATOR_TYPE,
    Builtin,
    Connector,
    Constant,
    Integrator,
    InterExtrapolation,
    Port,
    VectorIntegrator,
)

PREFIX = "com.avl.model.connect.ssp"
PORT = f"{PREFIX}.port"
CONNECTION = f"{PREFIX}.connection"
INTER_EXTRAPOLATION = f"{PREFIX}.connection.inter_extrapolation"
SPECIFIC_DATA = {
    CONSTANT_TYPE: f"{PREFIX}.component.constant",
    INTEGRATOR_TYPE: f"{PREFIX}.component.integrator",
    VECTOR_INTEGRATOR_TYPE: f"{PREFIX}.component.vector_integrator",
}
IGNORED = {
    f"{PREFIX}.config": "it is empty in OpenMCx",
    f"{PREFIX}.component.results": "Coupler records every communication point",
    f"{PREFIX}.component.fmu": "FMU logging and internal variables are not recorded",
}
"""OpenMCx annotations that change no value: read past with a warning."""
REFUSED = {
    f"{PREFIX}.parameter": "parameter arrays (p[k,j]) are not supported; bind each element "
    "with an ssv:Parameter",
    f"{PREFIX}.parameter.fmu": "isInitialValue is not supported; bind the value with an "
    "ssv:Parameter",
}
"""OpenMCx annotations Coupler cannot apply and that would change values: refused."""

MAX_VECTOR_ELEMENTS = 100_000
"""Elements one vector connector (or one slice of it) may have: an FMU's vector is as long as
the scalar variables it declares, and no FMU is bounded by a number written in the SSD; the
ceiling keeps a mistyped ``endIndex="1000000000"`` from being expanded into a billion
connectors before any FMU is asked."""
MAX_ELEMENTS = 200_000
"""Vector elements all the vector connectors of one SSD may have together (each becomes a
connector of its own, a few hundred bytes: about 100 MB at the ceiling)."""
MAX_SUB_STEPS = 1_000_000
"""An Integrator's ``numSubSteps`` at the most (each a call of the built-in per step)."""

_ORDERS = {"zero": 0, "first": 1}
_INTERVALS = ("coupling", "synchronization")
_SCALAR_PORTS = {
    "Real": (ValueType.REAL, ("min", "max", "scale", "offset", "default", "initial")),
    "Integer": (ValueType.INTEGER, ("min", "max", "scale", "offset", "default", "initial")),
    "Boolean": (ValueType.BOOLEAN, ("default", "initial")),
    "String": (ValueType.STRING, ("default", "initial")),
    "Binary": (ValueType.BINARY, ()),
    "BinaryReference": (ValueType.BINARY, ()),
}
_VECTOR_PORTS = {"RealVector": ValueType.REAL, "IntegerVector": ValueType.INTEGER}
_CONSTANT_VALUES = {
    "Real": ValueType.REAL,
    "Integer": ValueType.INTEGER,
    "String": ValueType.STRING,
    "Boolean": ValueType.BOOLEAN,
    "RealVector": ValueType.REAL,
    "IntegerVector": ValueType.INTEGER,
}


def annotation(owner: Element, kind: str) -> Element | None:
    """The content element of ``owner``'s annotation of type ``kind``, or None."""
    for group in (e for e in elements(owner) if local(e) == "Annotations"):
        for item in (e for e in elements(group) if local(e) == "Annotation"):
            if item.get("type") == kind:
                return next(elements(item), None)
    return None


def attributes(element: Element, known: Iterator[str] | tuple[str, ...], display: str) -> None:
    """ScenarioError naming the first attribute of ``element`` OpenMCx does not define."""
    allowed = set(known)
    unknown = [str(a) for a in element.attrib if a not in allowed and "}" not in str(a)]
    if unknown:
        raise ScenarioError(
            f"{where(display, element)}: <{local(element)}> has no attribute '{unknown[0]}' in "
            f"OpenMCx (attributes: {', '.join(sorted(allowed)) or 'none'}); remove it"
        )


def required_attribute(element: Element, name: str, display: str) -> str:
    value = element.get(name)
    if value is None:
        raise ScenarioError(
            f"{where(display, element)}: <{local(element)}> lacks the attribute '{name}' "
            "OpenMCx requires; add it"
        )
    return value


# -- which semantics ----------------------------------------------------------------------------

OWN = {PORT, CONNECTION, INTER_EXTRAPOLATION, *SPECIFIC_DATA.values()}
"""Annotations only OpenMCx defines (Coupler's own SSDs use the task, component deltaTime and
decoupling annotations with Coupler's semantics)."""


def semantics_reason(root: Element, display: str) -> str:
    """Why the document runs with OpenMCx's semantics: the first element only OpenMCx defines
    (a built-in component, a port, slice or inter/extrapolation annotation, a component that
    reads its inputs at the end of its step or has a trigger sequence, endType
    first_component), as ``file line N: ...``; empty when there is none."""
    for element in root.iter():
        if not isinstance(element.tag, str):
            continue
        tag = local(element)
        if tag == "Component" and element.get("type", "") in SPECIFIC_DATA:
            return (
                f"{where(display, element)}: component '{element.get('name', '')}' is "
                f"OpenMCx's built-in {element.get('type')}"
            )
        if tag == "Annotation" and element.get("type", "") in OWN:
            return f"{where(display, element)}: annotation '{element.get('type')}'"
        own = [a for a in ("inputAtEndTime", "triggerSequence") if a in element.attrib]
        if tag == "Component" and own:
            return f"{where(display, element)}: OpenMCx component attribute {own[0]}"
        if tag == "Task" and element.get("endType") == "first_component":
            return f'{where(display, element)}: OpenMCx endType="first_component"'
    return ""


# -- ports -----------------------------------------------------------------------------------


def read_ports(
    element: Element, connector: Connector, owner: str, display: str
) -> tuple[Connector, ...]:
    """The connector as the SSD's port annotation makes it: itself (with nameInModel and its
    port settings) or one connector per element of a vector."""
    port = annotation(element, PORT)
    if port is None:
        return (connector,)
    here = where(display, port)
    if local(port) != "Port":
        raise ScenarioError(f"{here}: {PORT} holds <{local(port)}>; write <mc:Port>")
    attributes(port, ("nameInModel", "id"), display)
    kinds = list(elements(port))
    if len(kinds) != 1 or local(kinds[0]) not in (*_SCALAR_PORTS, *_VECTOR_PORTS):
        given = ", ".join(f"<{local(k)}>" for k in kinds) or "nothing"
        raise ScenarioError(
            f"{here}: <mc:Port> of connector '{owner}.{connector.name}' holds {given}; it holds "
            f"exactly one of {', '.join(f'<{k}>' for k in (*_SCALAR_PORTS, *_VECTOR_PORTS))}"
        )
    typed = kinds[0]
    tag = local(typed)
    type_ = _SCALAR_PORTS[tag][0] if tag in _SCALAR_PORTS else _VECTOR_PORTS[tag]
    if connector.type is not None and connector.type is not type_:
        raise ScenarioError(
            f"{where(display, typed)}: connector '{owner}.{connector.name}' is {connector.type} "
            f"but its port is <{tag}>; make them agree"
        )
    in_model = port.get("nameInModel") or None
    connector = replace(connector, type=type_, name_in_model=in_model)
    if tag in _SCALAR_PORTS:
        settings = _SCALAR_PORTS[tag][1]
        attributes(typed, (*settings, "writeResults"), display)
        values = {name: _scalar(typed, name, type_, display) for name in settings}
        return (
            replace(
                connector,
                port=_port(values, boolean(typed, "writeResults", display, True)),
            ),
        )
    return _vector(typed, connector, in_model, owner, display)


def _vector(
    typed: Element, connector: Connector, in_model: str | None, owner: str, display: str
) -> tuple[Connector, ...]:
    settings = ("min", "max", "scale", "offset", "default", "initial")
    attributes(typed, ("startIndex", "endIndex", "writeResults", *settings), display)
    start = _index(typed, "startIndex", display)
    end = _index(typed, "endIndex", display)
    if end < start:
        raise ScenarioError(
            f"{where(display, typed)}: vector connector '{owner}.{connector.name}' has "
            f'startIndex="{start}" after endIndex="{end}"; give startIndex <= endIndex'
        )
    count = end - start + 1
    if count > MAX_VECTOR_ELEMENTS:
        raise ScenarioError(
            f"{where(display, typed)}: vector connector '{owner}.{connector.name}' has {count} "
            f'elements (startIndex="{start}" .. endIndex="{end}"); Coupler takes at most '
            f"{MAX_VECTOR_ELEMENTS} per vector, and an FMU's vector has no more elements than "
            "the variables it declares: give the FMU's own range"
        )
    assert connector.type is not None
    lists = {
        name: _list(typed, name, count, lambda text: _parse(connector.type, text), display)
        for name in settings
    }
    writes = _list(typed, "writeResults", count, _boolean, display)
    result = []
    for i in range(count):
        if i % 4096 == 4095:
            checkpoint()
        values = {name: (found[i] if found else None) for name, found in lists.items()}
        result.append(
            replace(
                connector,
                name=f"{connector.name}[{start + i}]",
                name_in_model=f"{in_model}[{start + i}]" if in_model else None,
                port=_port(values, bool(writes[i]) if writes else True),
                vector=connector.name,
            )
        )
    return tuple(result)


def _port(values: dict[str, Value | None], write_results: bool) -> Port:
    numbers = {
        k: float(v) for k in ("min", "max", "scale", "offset") if (v := values.get(k)) is not None
    }
    return Port(
        default=values.get("default"),
        initial=values.get("initial"),
        write_results=write_results,
        **numbers,
    )


def _index(element: Element, name: str, display: str) -> int:
    value = integer(element, name, display, None)
    if value is None:
        required_attribute(element, name, display)
    assert value is not None
    if value < 0:
        raise ScenarioError(
            f'{where(display, element)}: <{local(element)} {name}="{value}"> is negative; '
            "indices are unsigned"
        )
    return value


def _parse(type_: ValueType | None, text: str) -> Value:
    if type_ is ValueType.REAL:
        return float(text)
    if type_ is ValueType.INTEGER:
        return int(text)
    if type_ is ValueType.BOOLEAN:
        return _boolean(text)
    return text


def _boolean(text: str) -> bool:
    if text in ("true", "1"):
        return True
    if text in ("false", "0"):
        return False
    raise ValueError(f"'{text}' is not a boolean")


def _scalar(element: Element, name: str, type_: ValueType, display: str) -> Value | None:
    text = element.get(name)
    if text is None:
        return None
    try:
        return _parse(type_, text.strip() if type_ is not ValueType.STRING else text)
    except ValueError as exc:
        raise ScenarioError(
            f'{where(display, element)}: <{local(element)} {name}="{text}"> is not a {type_} '
            f"value; write one"
        ) from exc


def _list(
    element: Element,
    name: str,
    count: int,
    parse: Callable[[str], Value],
    display: str,
) -> list[Value] | None:
    text = element.get(name)
    if text is None:
        return None
    items = text.split()
    if len(items) != count:
        raise ScenarioError(
            f'{where(display, element)}: <{local(element)} {name}="{text}"> has {len(items)} '
            f"values for {count} elements; give one per element"
        )
    try:
        return [parse(item) for item in items]
    except ValueError as exc:
        raise ScenarioError(
            f'{where(display, element)}: <{local(element)} {name}="{text}">: {exc}'
        ) from exc


# -- what ports do to values ------------------------------------------------------------------


def port_input(connector: Connector) -> Callable[[Value], Value]:
    """What OpenMCx does to a value entering an input port: ``x * scale + offset`` (each only
    when given and not 0), then clamped to [min, max]."""
    return _transform(connector, clamp_first=False)


def port_output(connector: Connector) -> Callable[[Value], Value]:
    """What OpenMCx does to a value leaving an output port: clamped to [min, max] first, then
    ``x * scale + offset``."""
    return _transform(connector, clamp_first=True)


def _transform(connector: Connector, *, clamp_first: bool) -> Callable[[Value], Value]:
    port = connector.port
    if (
        port is None
        or not port.transforms
        or connector.type
        not in (
            ValueType.REAL,
            ValueType.INTEGER,
        )
    ):
        return _same
    number: Callable[[float], Value] = int if connector.type is ValueType.INTEGER else float
    low, high = port.min, port.max
    scale, offset = port.scale, port.offset

    def clamp(value: Value) -> Value:
        if low is not None and value <= low:
            return number(low)
        if high is not None and value >= high:
            return number(high)
        return value

    def linear(value: Value) -> Value:
        if scale:
            value = value * number(scale)
        if offset:
            value = value + number(offset)
        return value

    if clamp_first:
        return lambda value: linear(clamp(value))
    return lambda value: clamp(linear(value))


def _same(value: Value) -> Value:
    return value


# -- connections ------------------------------------------------------------------------------


def read_slices(
    connection: Element, display: str
) -> tuple[tuple[int, int] | None, tuple[int, int] | None]:
    """The (start, end) index ranges of a connection's ``mc:Connection``; None for a side
    that gives none (a scalar connector)."""
    content = annotation(connection, CONNECTION)
    if content is None:
        return None, None
    if local(content) != "Connection":
        raise ScenarioError(
            f"{where(display, content)}: {CONNECTION} holds <{local(content)}>; write "
            "<mc:Connection>"
        )
    attributes(content, (), display)
    sides: dict[str, tuple[int, int]] = {}
    for side in elements(content):
        if local(side) not in ("Start", "End") or local(side) in sides:
            raise ScenarioError(
                f"{where(display, side)}: <mc:Connection> holds <{local(side)}>; it holds at "
                "most one <mc:Start> and one <mc:End>"
            )
        attributes(side, ("startIndex", "endIndex"), display)
        first = _index(side, "startIndex", display)
        last = _index(side, "endIndex", display)
        if last < first:
            raise ScenarioError(
                f'{where(display, side)}: <mc:{local(side)} startIndex="{first}" '
                f'endIndex="{last}">: the end comes before the start; give startIndex <= '
                "endIndex"
            )
        if last - first + 1 > MAX_VECTOR_ELEMENTS:
            raise ScenarioError(
                f'{where(display, side)}: <mc:{local(side)} startIndex="{first}" '
                f'endIndex="{last}"> names {last - first + 1} elements; a vector connector has '
                f"at most {MAX_VECTOR_ELEMENTS}: give a range inside the connector's"
            )
        sides[local(side)] = (first, last)
    return sides.get("Start"), sides.get("End")


def read_inter_extrapolation(
    connection: Element, display: str, warnings: list[str]
) -> InterExtrapolation | None:
    """A connection's inter/extrapolation settings, or None."""
    content = annotation(connection, INTER_EXTRAPOLATION)
    if content is None:
        return None
    known = ("extrapolationOrder", "interpolationOrder")
    intervals = ("extrapolationInterval", "interpolationInterval")
    attributes(content, (*known, *intervals), display)
    orders = []
    for name in known:
        text = required_attribute(content, name, display)
        if text not in _ORDERS:
            raise ScenarioError(
                f'{where(display, content)}: <mc:InterExtrapolation {name}="{text}">: OpenMCx '
                "knows the orders zero and first"
            )
        orders.append(_ORDERS[text])
    for name, default in zip(intervals, ("synchronization", "coupling"), strict=True):
        text = content.get(name, default)
        if text not in _INTERVALS:
            raise ScenarioError(
                f'{where(display, content)}: <mc:InterExtrapolation {name}="{text}">: OpenMCx '
                "knows the intervals coupling and synchronization"
            )
        if text != default:
            raise ScenarioError(
                f'{where(display, content)}: <mc:InterExtrapolation {name}="{text}"> is not '
                f'supported (OpenMCx implements only {name}="{default}" for Reals); remove it'
            )
    return InterExtrapolation(extrapolation_order=orders[0], interpolation_order=orders[1])


# -- built-in components ----------------------------------------------------------------------


def read_builtin(
    element: Element, mime: str, connectors: tuple[Connector, ...], name: str, display: str
) -> Builtin:
    """The specific data of a built-in component, checked against its connectors."""
    here = where(display, element)
    if element.get("source", ""):
        raise ScenarioError(
            f"{here}: component '{name}' is an OpenMCx built-in ({mime}), which has no source; "
            'write source=""'
        )
    data = annotation(element, SPECIFIC_DATA[mime])
    if data is not None and local(data) != "SpecificData":
        raise ScenarioError(
            f"{where(display, data)}: {SPECIFIC_DATA[mime]} holds <{local(data)}>; write "
            "<mc:SpecificData>"
        )
    inputs = [c for c in connectors if c.kind == "input"]
    outputs = [c for c in connectors if c.kind == "output"]
    other = [c for c in connectors if c.kind not in ("input", "output")]
    if other:
        raise ScenarioError(
            f"{where(display, element)}: connector '{name}.{other[0].name}' is {other[0].kind}; "
            f"an OpenMCx built-in has inputs and outputs only"
        )
    if mime == CONSTANT_TYPE:
        return _constant(element, data, inputs, outputs, name, display)
    for c in connectors:
        if c.type not in (None, ValueType.REAL):
            raise ScenarioError(
                f"{where(display, element)} (connector line {c.line}): connector "
                f"'{name}.{c.name}' is {c.type}; an OpenMCx integrator integrates Reals"
            )
    if mime == INTEGRATOR_TYPE:
        if len(inputs) != 1 or len(outputs) > 1:
            raise ScenarioError(
                f"{here}: integrator '{name}' has {len(inputs)} input and {len(outputs)} output "
                "elements; OpenMCx's Integrator has exactly one input and at most one output"
            )
        if data is None:
            return Integrator()
        attributes(data, ("gain", "numSubSteps", "initialState"), display)
        sub_steps = integer(data, "numSubSteps", display, 1)
        assert sub_steps is not None
        if not 1 <= sub_steps <= MAX_SUB_STEPS:
            raise ScenarioError(
                f'{where(display, data)}: numSubSteps="{sub_steps}" must be between 1 and '
                f"{MAX_SUB_STEPS}"
            )
        return Integrator(
            gain=_finite(data, "gain", display, 1.0),
            initial_state=_finite(data, "initialState", display, 0.0),
            sub_steps=sub_steps,
        )
    if len(inputs) != len(outputs):
        raise ScenarioError(
            f"{here}: vector integrator '{name}' has {len(inputs)} input and {len(outputs)} "
            "output elements; OpenMCx's VectorIntegrator needs as many of each"
        )
    if data is None:
        return VectorIntegrator()
    attributes(data, ("initialState",), display)
    return VectorIntegrator(initial_state=_finite(data, "initialState", display, 0.0))


def _finite(element: Element, name: str, display: str, default: float) -> float:
    """A built-in's number: a NaN or infinite one would be written into every result row."""
    value = number(element, name, display, default)
    assert value is not None
    if not math.isfinite(value):
        raise ScenarioError(
            f'{where(display, element)}: <mc:{local(element)} {name}="{element.get(name)}"> is '
            "not a finite number; give a decimal number"
        )
    return value


def _constant(
    element: Element,
    data: Element | None,
    inputs: list[Connector],
    outputs: list[Connector],
    name: str,
    display: str,
) -> Constant:
    here = where(display, element)
    if inputs:
        raise ScenarioError(
            f"{here}: constant '{name}' has an input '{inputs[0].name}'; an OpenMCx Constant "
            "has outputs only"
        )
    groups: list[list[Connector]] = []
    for c in outputs:  # a vector connector's elements are one group, a scalar one of one
        if groups and c.vector is not None and groups[-1][0].vector == c.vector:
            groups[-1].append(c)
        else:
            groups.append([c])
    items = list(elements(data)) if data is not None else []
    if len(items) != len(groups):
        raise ScenarioError(
            f"{where(display, data if data is not None else element)}: constant '{name}' has "
            f"{len(groups)} output connectors but {len(items)} values in <mc:SpecificData>; "
            "give one value (or vector of values) per output connector, in order"
        )
    values: list[Value] = []
    for group, item in zip(groups, items, strict=True):
        tag = local(item)
        label = group[0].vector or group[0].name
        if tag not in _CONSTANT_VALUES:
            raise ScenarioError(
                f"{where(display, item)}: <{tag}> is not a Constant value; write one of "
                f"{', '.join(f'<mc:{k}>' for k in _CONSTANT_VALUES)}"
            )
        attributes(item, ("value",), display)
        text = required_attribute(item, "value", display)
        type_ = _CONSTANT_VALUES[tag]
        if group[0].type is not None and group[0].type is not type_:
            raise ScenarioError(
                f"{where(display, item)}: <mc:{tag}> is the value of output '{name}.{label}', "
                f"which is {group[0].type}; give a value of its type"
            )
        texts = text.split() if tag.endswith("Vector") else [text]
        if len(texts) != len(group):
            raise ScenarioError(
                f'{where(display, item)}: <mc:{tag} value="{text}"> has {len(texts)} values for '
                f"output '{name}.{label}' of {len(group)} elements; give one per element"
            )
        try:
            parsed = [_parse(type_, t) for t in texts]
            if any(isinstance(v, float) and not math.isfinite(v) for v in parsed):
                raise ValueError("not finite")
            values.extend(parsed)
        except ValueError as exc:
            raise ScenarioError(
                f'{where(display, item)}: <mc:{tag} value="{text}"> is not a '
                f"{'finite ' if type_ is ValueType.REAL else ''}{type_} value"
            ) from exc
    return Constant(values=tuple(values))
