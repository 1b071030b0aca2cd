"""Parameter bindings: ``.ssv`` parameter sets (inline or files), ``.ssm`` mappings, prefixes."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

from coupler.channels import Value, ValueType
from coupler.errors import ScenarioError, ValidationError
from coupler.values import parse, widen

from .documents import Element, boolean, child, children, elements, line_of, local, required, where
from .model import (
    BooleanMappingTransformation,
    Component,
    Enumeration,
    EnumerationMappingTransformation,
    IntegerMappingTransformation,
    LinearTransformation,
    ParameterValue,
    Transformation,
    Unit,
    frozen_mapping,
)
from .transformations import read_transformation
from .units import UndefinedUnit, UndefinedUnits, read_units, unit_converter

PARAMETER_SET = "application/x-ssp-parameter-set"
PARAMETER_MAPPING = "application/x-ssp-parameter-mapping"

#: Opens a referenced file: (source attribute, referencing element, referencing file) ->
#: (root element, display name). Validates it against its schema.
Opener = Callable[[str, Element, str], tuple[Element, str]]


@dataclass(frozen=True, kw_only=True)
class BoundParameter:
    """One parameter of a binding, after prefix and mapping, before it reaches a component."""

    name: str
    value: ParameterValue
    units: Mapping[str, Unit]
    """Units of the file the value came from (ssv-local units)."""
    suppress_unit_conversion: bool = False


@dataclass(frozen=True, kw_only=True)
class _Entry:
    target: str
    transformation: Transformation | None
    suppress_unit_conversion: bool
    where: str


def read_binding(
    binding: Element,
    display: str,
    *,
    open_file: Opener,
    enumerations: Mapping[str, Enumeration],
    warn: Callable[[str], None],
) -> list[BoundParameter]:
    """The parameters one ``ssd:ParameterBinding`` supplies, in file order."""
    here = where(display, binding)
    kind = binding.get("type", PARAMETER_SET)
    if kind != PARAMETER_SET:
        warn(f"{here}: ParameterBinding of type '{kind}' is not supported; ignored")
        return []
    if binding.get("sourceBase", "SSD") == "component":
        warn(
            f'{here}: ParameterBinding with sourceBase="component" (a file inside the FMU) '
            "is not supported; ignored"
        )
        return []
    source = binding.get("source")
    if source:
        root, set_display = open_file(source, binding, display)
    else:
        values = child(binding, "ParameterValues")
        inline = child(values, "ParameterSet") if values is not None else None
        set_display = display
        if inline is None:
            warn(f"{here}: ParameterBinding has neither a source nor inline ParameterValues")
            return []
        root = inline
    units = read_units(child(root, "Units"), set_display)
    local_enums = _enumerations(child(root, "Enumerations"), set_display)
    parameters = read_parameter_set(root, set_display, {**enumerations, **local_enums})
    mapping = _mapping(binding, display, open_file=open_file, warn=warn)
    prefix = binding.get("prefix", "")
    names = {prefix + name for name, _ in parameters}
    unknown = [entry for source, entry in mapping.items() if source not in names]
    if unknown:
        raise ValidationError(
            [
                f"{entry.where}: parameter mapping source '{source}' names no parameter of the "
                f"set it maps ({set_display}: {', '.join(sorted(names)) or 'none'}); fix the "
                "name or remove the entry"
                for source, entry in mapping.items()
                if entry in unknown
            ],
            subject=display,
        )
    result = []
    for name, value in parameters:
        full = prefix + name
        entry = mapping.get(full)
        if entry is None:
            result.append(BoundParameter(name=full, value=value, units=units))
            continue
        mapped = _transform(value, entry, {**enumerations, **local_enums})
        result.append(
            BoundParameter(
                name=entry.target,
                value=mapped,
                units=units,
                suppress_unit_conversion=entry.suppress_unit_conversion,
            )
        )
    return result


def read_parameter_set(
    root: Element, display: str, enumerations: Mapping[str, Enumeration]
) -> list[tuple[str, ParameterValue]]:
    """(name, value) of each ``ssv:Parameter`` of an ``ssv:ParameterSet``."""
    params = child(root, "Parameters")
    result: list[tuple[str, ParameterValue]] = []
    lines: dict[str, int] = {}
    for parameter in children(params, "Parameter") if params is not None else ():
        name = required(parameter, "name", display)
        if name in lines:
            raise ScenarioError(
                f"{where(display, parameter)}: parameter '{name}' is given twice in this "
                f"parameter set (first on line {lines[name]}); keep one value"
            )
        lines[name] = line_of(parameter)
        typed = next((e for e in elements(parameter) if local(e) != "Annotations"), None)
        if typed is None:
            raise ScenarioError(
                f"{where(display, parameter)}: parameter '{name}' has no value element"
            )
        result.append((name, _value(typed, display, enumerations)))
    return result


def _value(
    element: Element, display: str, enumerations: Mapping[str, Enumeration]
) -> ParameterValue:
    kind = local(element)
    text = required(element, "value", display)
    origin = where(display, element)
    try:
        type_ = ValueType(kind)
    except ValueError as exc:
        raise ScenarioError(f"{origin}: unknown parameter type <{kind}>") from exc
    value: Value
    try:
        if type_ is ValueType.ENUMERATION:
            value = _enum_value(element, text, origin, enumerations)
        else:
            value = parse(type_, text)
    except ValueError as exc:
        raise ScenarioError(f'{origin}: value "{text}" is not a valid {kind}') from exc
    return ParameterValue(value=value, type=type_, unit=element.get("unit"), origin=origin)


def _enum_value(
    element: Element, text: str, origin: str, enumerations: Mapping[str, Enumeration]
) -> int:
    enum_name = element.get("name")
    enum = enumerations.get(enum_name) if enum_name else None
    if enum is None:
        raise ScenarioError(
            f'{origin}: Enumeration parameter needs name="..." naming an enumeration defined in '
            f"the .ssv or the SSD (known: {', '.join(enumerations) or 'none'})"
        )
    if text not in enum.items:
        raise ScenarioError(
            f"{origin}: '{text}' is not an item of enumeration '{enum.name}' "
            f"(items: {', '.join(enum.items)})"
        )
    return enum.items[text]


def _enumerations(element: Element | None, display: str) -> dict[str, Enumeration]:
    result: dict[str, Enumeration] = {}
    for enum in children(element, "Enumeration") if element is not None else ():
        items = {}
        for item in children(enum, "Item"):
            items[required(item, "name", display)] = int(required(item, "value", display))
        name = required(enum, "name", display)
        result[name] = Enumeration(name=name, items=items)
    return result


read_enumerations = _enumerations


def _mapping(
    binding: Element, display: str, *, open_file: Opener, warn: Callable[[str], None]
) -> dict[str, _Entry]:
    element = child(binding, "ParameterMapping")
    if element is None:
        return {}
    kind = element.get("type", PARAMETER_MAPPING)
    if kind != PARAMETER_MAPPING:
        warn(
            f"{where(display, element)}: ParameterMapping of type '{kind}' is not supported; "
            "ignored"
        )
        return {}
    if element.get("sourceBase", "SSD") == "component":
        warn(
            f'{where(display, element)}: ParameterMapping with sourceBase="component" is '
            "not supported; ignored"
        )
        return {}
    source = element.get("source")
    if source:
        root, map_display = open_file(source, element, display)
    else:
        inline = child(element, "ParameterMapping")
        if inline is None:
            warn(
                f"{where(display, element)}: ParameterMapping has neither a source nor "
                "inline content"
            )
            return {}
        root, map_display = inline, display
    entries = {}
    for entry in children(root, "MappingEntry"):
        entries[required(entry, "source", map_display)] = _Entry(
            target=required(entry, "target", map_display),
            transformation=read_transformation(entry, map_display),
            suppress_unit_conversion=boolean(entry, "suppressUnitConversion", map_display, False),
            where=where(map_display, entry),
        )
    return entries


def _transform(
    value: ParameterValue, entry: _Entry, enumerations: Mapping[str, Enumeration]
) -> ParameterValue:
    t = entry.transformation
    if t is None:
        return value
    v = value.value
    problem = (
        f"{entry.where}: {type(t).__name__} cannot apply to {value.type} parameter ({value.origin})"
    )
    if isinstance(t, LinearTransformation):
        if value.type not in (ValueType.REAL, ValueType.INTEGER):
            raise ScenarioError(problem)
        new: Value = t.factor * float(v) + t.offset
        type_ = ValueType.REAL
    elif isinstance(t, BooleanMappingTransformation):
        if value.type is not ValueType.BOOLEAN:
            raise ScenarioError(problem)
        new, type_ = t.mapping.get(bool(v), bool(v)), value.type
    elif isinstance(t, IntegerMappingTransformation):
        if value.type is not ValueType.INTEGER:
            raise ScenarioError(problem)
        new, type_ = t.mapping.get(int(v), int(v)), value.type
    else:
        assert isinstance(t, EnumerationMappingTransformation)
        if value.type is not ValueType.ENUMERATION:
            raise ScenarioError(problem)
        new, type_ = _map_enum(int(v), t, enumerations), value.type
    return ParameterValue(
        value=new, type=type_, unit=value.unit, origin=f"{value.origin} via {entry.where}"
    )


def _map_enum(
    value: int, t: EnumerationMappingTransformation, enums: Mapping[str, Enumeration]
) -> int:
    for enum in enums.values():
        names = {v: k for k, v in enum.items.items()}
        name = names.get(value)
        if name is not None and t.mapping.get(name, name) in enum.items:
            return enum.items[t.mapping.get(name, name)]
    return value


# --- applying bindings to components -----------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Binding:
    """A ParameterBinding where it was found in the system tree."""

    depth: int
    """Nesting depth of its system or component (root = 0)."""
    order: int
    """Order of appearance, for ties."""
    scope: tuple[str, ...]
    """Path of the system or component it belongs to."""
    is_component: bool
    """Bound on a component (names are the component's) or on a system (names carry a path)."""
    parameters: tuple[BoundParameter, ...]


def apply_bindings(
    components: Mapping[tuple[str, ...], Component],
    systems: Mapping[tuple[str, ...], Mapping[str, str]],
    bindings: list[Binding],
    units: Mapping[str, Unit],
    *,
    warnings: list[str],
    problems: list[str],
    undefined: UndefinedUnits,
) -> tuple[Component, ...]:
    """Components with their parameters; deeper bindings first, so higher levels win (a unit
    that is not defined goes to ``undefined``: one problem per unit)."""
    values: dict[tuple[str, ...], dict[str, ParameterValue]] = {p: {} for p in components}
    for binding in sorted(bindings, key=lambda b: (-b.depth, b.order)):
        for parameter in binding.parameters:
            target = _target(components, systems, binding, parameter, warnings)
            if target is None:
                continue
            path, name = target
            try:
                values[path][name] = _fit(components[path], name, parameter, units)
            except UndefinedUnit as exc:
                undefined.report(exc)
            except ScenarioError as exc:
                problems.append(str(exc))
    return tuple(replace(c, parameters=frozen_mapping(values[p])) for p, c in components.items())


def _target(
    components: Mapping[tuple[str, ...], Component],
    systems: Mapping[tuple[str, ...], Mapping[str, str]],
    binding: Binding,
    parameter: BoundParameter,
    warnings: list[str],
) -> tuple[tuple[str, ...], str] | None:
    """(component path, parameter name) a bound parameter reaches, or None (warned)."""
    if binding.is_component:
        return binding.scope, parameter.name
    parts = tuple(parameter.name.split("."))
    for i in range(len(parts) - 1, 0, -1):
        candidate = binding.scope + parts[:i]
        if candidate in components:
            return candidate, ".".join(parts[i:])
    system = ".".join(binding.scope) or "the root system"
    if parameter.name in systems.get(binding.scope, {}):
        warnings.append(
            f"{parameter.value.origin}: parameter '{parameter.name}' binds a connector of "
            f"{system}; system-connector parameters are not propagated, ignored - bind the "
            "component's parameter instead"
        )
    else:
        warnings.append(
            f"{parameter.value.origin}: parameter '{parameter.name}' matches no component in "
            f"{system}; ignored (use Component.parameter names or a prefix)"
        )
    return None


def _fit(
    component: Component, name: str, parameter: BoundParameter, units: Mapping[str, Unit]
) -> ParameterValue:
    """The value converted to the connector's type and unit, when the SSD declares one."""
    value = parameter.value
    connector = component.connector(name)
    if connector is None or connector.type is None:
        return value
    what = f"{value.origin}: parameter '{component.name}.{name}'"
    if connector.type is not value.type:
        widened = widen(connector.type, value.value)
        if widened is value.value:
            raise ScenarioError(
                f"{what} is {value.type} but the connector is {connector.type}; "
                f"give a {connector.type} value"
            )
        value = replace(value, value=widened, type=connector.type)
    if (
        connector.unit
        and value.unit
        and connector.unit != value.unit
        and not parameter.suppress_unit_conversion
    ):
        convert = unit_converter(
            {**units, **parameter.units},
            value.unit,
            connector.unit,
            place=value.origin,
            user=f"parameter '{component.name}.{name}'",
        )
        if convert is not None:
            return replace(value, value=convert(float(value.value)), unit=connector.unit)
    return value
