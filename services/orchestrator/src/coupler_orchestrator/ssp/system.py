"""Walking an SSD's system tree: components, connectors, signal dictionaries, raw connections
and parameter bindings, collected into a ``Tree`` for flattening (``graph``) and parameter
resolution (``parameters``)."""

from __future__ import annotations

import difflib
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from coupler.channels import ValueType
from coupler.client import parse_address
from coupler.errors import ScenarioError, ValidationError

from . import openmcx
from . import tool_annotations as notes
from .documents import (
    Element,
    boolean,
    checkpoint,
    child,
    children,
    elements,
    line_of,
    local,
    required,
    where,
)
from .expansion import expand, variables_in
from .files import Documents
from .graph import Edge, Graph, Node
from .model import (
    BUILTIN_TYPES,
    FMU_TYPE,
    GRPC_TYPE,
    REPLAY_SCHEME,
    SUPPORTED_COMPONENT_TYPES,
    Component,
    Connector,
    DictionaryEntry,
    Enumeration,
    SignalDictionary,
    Unit,
)
from .parameters import Binding, read_binding
from .transformations import read_transformation
from .units import UndefinedUnit, UndefinedUnits, read_units

TYPES = {
    **{t.value: t for t in ValueType},
    # SSP 2.0 names
    "Float64": ValueType.REAL,
    "Float32": ValueType.REAL,
    **{f"{s}Int{n}": ValueType.INTEGER for s in ("", "U") for n in (8, 16, 32, 64)},
}
"""Connector type elements, SSP 1.0 and 2.0 names."""
_KINDS = ("input", "output", "parameter", "calculatedParameter", "inout")
_GRAPHICAL = {"ElementGeometry", "SystemGeometry", "GraphicalElements", "ConnectorGeometry"}


@dataclass
class Tree:
    """What the walk collects, by path in the system tree."""

    components: dict[tuple[str, ...], Component] = field(default_factory=dict)
    systems: dict[tuple[str, ...], dict[str, str]] = field(default_factory=dict)
    """System path -> its own connectors (name -> kind)."""
    dictionaries: dict[tuple[str, ...], SignalDictionary] = field(default_factory=dict)
    """System path + dictionary name -> dictionary."""
    bindings: list[Binding] = field(default_factory=list)
    graph: Graph = field(default_factory=Graph)


class Names:
    """Names that must be unique in one scope (a system's elements, a component's connectors):
    a second one is a problem naming both lines, never a silent replacement of the first."""

    def __init__(self, display: str, what: str, scope: str) -> None:
        self.display = display
        self.what = what
        self.scope = scope
        self.lines: dict[str, int] = {}

    def first(self, name: str, element: Element, problems: list[str]) -> bool:
        """Whether ``name`` is new here; a repeated one is added to ``problems``."""
        line = line_of(element)
        if name not in self.lines:
            self.lines[name] = line
            return True
        earlier = self.lines[name]
        problems.append(
            f"{self.display} line {line}: {self.what} '{name}' {self.scope} is already defined "
            f"at line {earlier}; names must be unique there - rename or remove one of the two"
        )
        return False


def _span(owner: str, names: list[str]) -> str:
    prefix = f"{owner}." if owner else ""
    first, last = f"{prefix}{names[0]}", f"{prefix}{names[-1]}"
    return first if len(names) == 1 else f"{first} .. {last}"


class SystemReader:
    """Reads one SSD's system tree; problems and warnings are collected, not raised."""

    def __init__(
        self,
        display: str,
        documents: Documents,
        *,
        units: dict[str, Unit],
        enumerations: Mapping[str, Enumeration],
        env: Mapping[str, str],
        warnings: list[str],
        problems: list[str],
        undefined: UndefinedUnits,
    ) -> None:
        self.display = display
        self.documents = documents
        self.units = units
        self.enumerations = enumerations
        self.env = env
        self.warnings = warnings
        self.problems = problems
        self.undefined = undefined
        self.tree = Tree()
        self.elements = 0
        """Vector elements read so far (``openmcx.MAX_ELEMENTS`` at the most)."""
        self._vectors: dict[tuple[str | None, ...], dict[str, list[str]]] = {}
        """Each component's vector connectors: their elements' names, in order."""

    def walk(self, system: Element, path: tuple[str, ...]) -> None:
        """Collect components, connectors, dictionaries, bindings and raw connections."""
        own = {}
        connectors = child(system, "Connectors")
        system_name = ".".join(path) or system.get("name", "")
        named = Names(self.display, "connector", f"of system '{system_name}'")
        for c in children(connectors, "Connector") if connectors is not None else ():
            name = required(c, "name", self.display)
            if named.first(name, c, self.problems):
                own[name] = c.get("kind", "")
        self.tree.systems[path] = own
        dictionaries = child(system, "SignalDictionaries")
        for d in children(dictionaries, "SignalDictionary") if dictionaries is not None else ():
            self.guard(self.read_dictionary, d, path)
        elements_ = child(system, "Elements")
        kinds: dict[str, str] = {}
        refs: dict[str, tuple[tuple[str, ...], Element]] = {}
        unique = Names(self.display, "element", f"in system '{system_name}'")
        for element in elements(elements_) if elements_ is not None else ():
            kind = local(element)
            name = element.get("name", "")
            if not unique.first(name, element, self.problems):
                continue
            kinds[name] = kind
            if kind == "Component":
                self.guard(self.read_component, element, (*path, name))
            elif kind == "System":
                self.walk(element, (*path, name))
            elif kind == "SignalDictionaryReference":
                found = self.find_dictionary(element, path)
                if found is not None:
                    refs[name] = (found, element)
            else:
                self.warnings.append(
                    f"{where(self.display, element)}: element <{kind}> is not supported; ignored"
                )
        self.read_bindings(system, path, is_component=False)
        connections = child(system, "Connections")
        for c in children(connections, "Connection") if connections is not None else ():
            self.guard(self.read_connection, c, path, kinds, refs)

    def guard(self, method: object, *args: object) -> None:
        """Run ``method``; collect a ScenarioError as a problem and go on."""
        try:
            method(*args)  # type: ignore[operator]
        except ValidationError as exc:
            self.problems.extend(exc.problems)
        except ScenarioError as exc:
            self.problems.append(str(exc))

    def read_component(self, element: Element, path: tuple[str, ...]) -> None:
        name = ".".join(path)
        here = where(self.display, element)
        mime = element.get("type", FMU_TYPE)
        if mime not in SUPPORTED_COMPONENT_TYPES:
            builtins = ", ".join(BUILTIN_TYPES)
            raise ScenarioError(
                f"{here}: component '{name}' has type '{mime}', which is not supported; "
                f"use {FMU_TYPE} or {GRPC_TYPE} (or one of OpenMCx's built-ins: {builtins})"
            )
        what = f"{here}: component '{name}'"
        written = required(element, "source", self.display)
        source = expand(written, self.env, what=what)
        # a problem quotes the source as written: ${VAR} named, its value never shown
        expanded = variables_in(written)
        shown = (
            f"'{written}' (with {', '.join(expanded)} from the environment)"
            if expanded
            else f"'{source}'"
        )
        for other, kind in openmcx.SPECIFIC_DATA.items():
            if other != mime and openmcx.annotation(element, kind) is not None:
                raise ScenarioError(
                    f"{here}: component '{name}' of type '{mime}' carries the annotation "
                    f"'{kind}', which belongs to {other}; remove it or fix the type"
                )
        connectors = self.read_connectors(element, name)
        builtin = None
        if mime in BUILTIN_TYPES:
            builtin = openmcx.read_builtin(element, mime, connectors, name, self.display)
        elif mime == FMU_TYPE and not source.startswith(REPLAY_SCHEME):
            fmu = self.documents.resolve(source, element, self.display, what="FMU", shown=shown)
            if not fmu.is_file():
                looked = "" if expanded else f" (looked for {fmu})"
                raise ScenarioError(
                    f"{what}: FMU file {shown} does not exist{looked}; add the FMU "
                    "to the archive/directory or fix the source attribute"
                )
            source = str(fmu)
        elif source.startswith(REPLAY_SCHEME):  # a recording stands in for the participant
            raw, sep, recorded = source.removeprefix(REPLAY_SCHEME).partition("#")
            recording = Path(raw)
            if raw and not recording.is_absolute():
                recording = self.documents.resolve(
                    raw, element, self.display, what="recording", shown=shown
                )
            source = f"{REPLAY_SCHEME}{recording if raw else ''}{sep}{recorded}"
        else:
            _check_address(source, what, shown)
        implementation = element.get("implementation", "any")
        if implementation == "ModelExchange":
            self.warnings.append(
                f"{here}: component '{name}' asks for implementation=\"ModelExchange\", which is "
                "not supported; it runs as co-simulation"
            )
        delta_time, input_at_end_time, trigger_sequence = notes.component_task(
            element, self.display
        )
        self.tree.components[path] = Component(
            name=name,
            type=mime,
            source=source,
            connectors=connectors,
            implementation=implementation,
            delta_time=delta_time,
            input_at_end_time=input_at_end_time,
            trigger_sequence=trigger_sequence,
            builtin=builtin,
            settings=notes.component_settings(
                element,
                self.display,
                lambda source, what: self.documents.resolve(
                    source, element, self.display, what=what
                ),
            ),
            file=self.display,
            line=line_of(element),
        )
        self.read_bindings(element, path, is_component=True)
        for item in elements(element):
            if local(item) not in ("Connectors", "ParameterBindings", "Annotations", *_GRAPHICAL):
                self.warnings.append(
                    f"{where(self.display, item)}: <{local(item)}> in component '{name}' "
                    "is not supported; ignored"
                )

    def read_connectors(self, element: Element, owner: str) -> tuple[Connector, ...]:
        result: list[Connector] = []
        connectors = child(element, "Connectors")
        unique = Names(self.display, "connector", f"of component '{owner}'")
        for c in children(connectors, "Connector") if connectors is not None else ():
            name = required(c, "name", self.display)
            if not unique.first(name, c, self.problems):
                continue
            kind = required(c, "kind", self.display)
            if kind not in _KINDS:
                raise ScenarioError(
                    f"{where(self.display, c)}: connector '{owner}.{name}' has kind '{kind}'; "
                    f"use one of {', '.join(_KINDS)}"
                )
            typed = next(
                (
                    e
                    for e in elements(c)
                    if local(e) in TYPES
                    or local(e) not in ("ConnectorGeometry", "Annotations", "Dimension")
                ),
                None,
            )
            type_ = None
            unit = enumeration = mime = None
            if typed is not None:
                tag = local(typed)
                if tag not in TYPES:
                    raise ScenarioError(
                        f"{where(self.display, typed)}: connector '{owner}.{name}' has type "
                        f"<{tag}>, which is not supported; use Real, Integer, Boolean, String, "
                        "Enumeration or Binary"
                    )
                type_ = TYPES[tag]
                unit = typed.get("unit")
                if unit is not None and unit not in self.units:
                    self.undefined.report(
                        UndefinedUnit(
                            unit,
                            where(self.display, typed),
                            f"connector '{owner}.{name}'",
                            self.units,
                        )
                    )
                    unit = None  # the connector stays, so nothing else fails for this cause
                if type_ is ValueType.ENUMERATION:
                    enumeration = typed.get("name")
                    if enumeration not in self.enumerations:
                        raise ScenarioError(
                            f"{where(self.display, typed)}: connector '{owner}.{name}' uses "
                            f"enumeration '{enumeration}', which is not defined in <Enumerations>"
                        )
                if type_ is ValueType.BINARY:
                    mime = typed.get("mime-type", "application/octet-stream")
            connector = Connector(
                name=name,
                kind=kind,
                type=type_,
                unit=unit,
                enumeration=enumeration,
                mime_type=mime,
                line=line_of(c),
            )
            result.extend(openmcx.read_ports(c, connector, owner, self.display))
        self.elements += sum(1 for c in result if c.vector is not None)
        if self.elements > openmcx.MAX_ELEMENTS:
            raise ScenarioError(
                f"{where(self.display, element)}: component '{owner}' brings the SSD's vector "
                f"connectors to {self.elements} elements; Coupler takes at most "
                f"{openmcx.MAX_ELEMENTS} in one SSD (each is a connector of its own)"
            )
        twice = sorted(n for n, count in Counter(c.name for c in result).items() if count > 1)
        if twice:
            raise ScenarioError(
                f"{where(self.display, element)}: component '{owner}' declares connector "
                f"'{twice[0]}' more than once (a vector's elements count); rename one"
            )
        return tuple(result)

    def read_dictionary(self, element: Element, path: tuple[str, ...]) -> None:
        name = required(element, "name", self.display)
        source = element.get("source")
        if source:
            root, display = self.documents.open(source, element, self.display)
        else:
            inline = child(element, "SignalDictionary")
            display = self.display
            if inline is None:
                raise ScenarioError(
                    f"{where(self.display, element)}: signal dictionary '{name}' has neither a "
                    "source nor inline content"
                )
            root = inline
        for unit_name, unit in read_units(child(root, "Units"), display).items():
            known = self.units.setdefault(unit_name, unit)
            if known.base_unit != unit.base_unit:
                self.warnings.append(
                    f"{display} line {unit.line}: unit '{unit_name}' differs from the SSD's "
                    "definition; the SSD's applies"
                )
        entries = {}
        for entry in children(root, "DictionaryEntry"):
            entry_name = required(entry, "name", display)
            typed = next((e for e in elements(entry) if local(e) in TYPES), None)
            entries[entry_name] = DictionaryEntry(
                name=entry_name,
                type=TYPES[local(typed)] if typed is not None else None,
                unit=typed.get("unit") if typed is not None else None,
            )
        self.tree.dictionaries[(*path, name)] = SignalDictionary(
            name=name, entries=entries, file=display, line=line_of(element)
        )

    def find_dictionary(self, element: Element, path: tuple[str, ...]) -> tuple[str, ...] | None:
        """The key of the dictionary a reference names, looked up from ``path`` upwards."""
        name = element.get("dictionary", "")
        for depth in range(len(path), -1, -1):
            key = (*path[:depth], name)
            if key in self.tree.dictionaries:
                return key
        self.problems.append(
            f"{where(self.display, element)}: SignalDictionaryReference "
            f"'{element.get('name', '')}' names dictionary '{name}', which is not defined in "
            "this system or an enclosing one; add it to <SignalDictionaries>"
        )
        return None

    def read_connection(
        self,
        element: Element,
        path: tuple[str, ...],
        kinds: dict[str, str],
        refs: dict[str, tuple[tuple[str, ...], Element]],
    ) -> None:
        start_el, end_el = element.get("startElement"), element.get("endElement")
        if any(
            kinds.get(e) == "Component" and (*path, e) not in self.tree.components
            for e in (start_el, end_el)
            if e
        ):
            return  # a component that could not be loaded: its own problem says why, once
        start_c = required(element, "startConnector", self.display)
        end_c = required(element, "endConnector", self.display)
        start = f"{start_el}.{start_c}" if start_el else start_c
        label = f"{start} -> {f'{end_el}.{end_c}' if end_el else end_c}"
        what = f"{where(self.display, element)}: connection {label}"
        starts = self.elements_of(what, path, start_el, start_c, "Start", element)
        ends = self.elements_of(what, path, end_el, end_c, "End", element)
        if len(starts) != len(ends):
            raise ScenarioError(
                f"{what}: {len(starts)} elements ({_span(start_el or '', starts)}) cannot drive "
                f"{len(ends)} ({_span(end_el or '', ends)}); give ranges of the same length in "
                "<mc:Connection>"
            )
        decoupled, decouple_type, priority = notes.decoupling(element, self.display)
        edge = Edge(
            transformation=read_transformation(element, self.display),
            suppress_unit_conversion=boolean(
                element, "suppressUnitConversion", self.display, False
            ),
            decoupled=decoupled,
            decouple_type=decouple_type,
            decouple_priority=priority,
            inter_extrapolation=openmcx.read_inter_extrapolation(
                element, self.display, self.warnings
            ),
            file=self.display,
            line=line_of(element),
            label=label,
        )
        for i, (a_name, b_name) in enumerate(zip(starts, ends, strict=True)):
            if i % 4096 == 4095:
                checkpoint()
            a = self.endpoint(what, path, start_el, a_name, kinds, refs, start=True)
            b = self.endpoint(what, path, end_el, b_name, kinds, refs, start=False)
            self.tree.graph.add(a, b, edge)

    def elements_of(
        self,
        what: str,
        path: tuple[str, ...],
        element: str | None,
        connector: str,
        side: str,
        connection: Element,
    ) -> list[str]:
        """The connector names one end of a connection stands for: itself, or the elements of
        an OpenMCx vector connector its ``mc:Connection`` slice names."""
        ranges = openmcx.read_slices(connection, self.display)
        span = ranges[0] if side == "Start" else ranges[1]
        component = self.tree.components.get((*path, element)) if element else None
        if component is None:  # a system connector, a dictionary entry or an unknown element
            if span is not None:
                raise ScenarioError(
                    f"{what}: <mc:{side}> gives indices for '{connector}', which is not a "
                    "component's vector connector"
                )
            return [connector]
        key = (*path, element)
        if key not in self._vectors:
            vectors: dict[str, list[str]] = {}
            for c in component.connectors:
                if c.vector is not None:
                    vectors.setdefault(c.vector, []).append(c.name)
            self._vectors[key] = vectors
        vector = self._vectors[key].get(connector, [])
        if span is None:
            if vector:
                raise ScenarioError(
                    f"{what}: '{element}.{connector}' is a vector connector ({vector[0]} .. "
                    f"{vector[-1]}); name the elements with <mc:Connection><mc:{side} "
                    'startIndex="..." endIndex="..."/></mc:Connection>'
                )
            return [connector]
        if not vector:
            raise ScenarioError(
                f"{what}: <mc:{side}> gives indices for '{element}.{connector}', which is a "
                "scalar connector (OpenMCx allows indices on vector connectors only); remove "
                f"<mc:{side}>"
            )
        first, last = span
        lowest, highest = (int(name[len(connector) + 1 : -1]) for name in (vector[0], vector[-1]))
        if first < lowest or last > highest:
            raise ScenarioError(
                f"{what}: the slice {element}.{connector}[{first}..{last}] is out of range: "
                f"'{element}.{connector}' has the elements {vector[0]} .. {vector[-1]}"
            )
        return [f"{connector}[{i}]" for i in range(first, last + 1)]

    def endpoint(
        self,
        what: str,
        path: tuple[str, ...],
        element: str | None,
        connector: str,
        kinds: dict[str, str],
        refs: dict[str, tuple[tuple[str, ...], Element]],
        *,
        start: bool,
    ) -> Node:
        """The graph node of one end of a connection (``start``: where it starts), with its
        role seen from the system."""
        if not element:
            own = self.tree.systems[path]
            if connector not in own:
                system = ".".join(path) or "the root system"
                raise ScenarioError(
                    f"{what}: connector '{connector}' does not exist on {system} "
                    f"(connectors: {', '.join(own) or 'none'})"
                )
            role = {
                "input": "source",
                "parameter": "source",
                "output": "sink",
                "calculatedParameter": "sink",
            }
            return Node(
                key=("sys", *path, connector), role=role.get(own[connector]), label=connector
            )
        kind = kinds.get(element)
        if kind is None:
            raise ScenarioError(
                f"{what}: element '{element}' does not exist in system "
                f"'{'.'.join(path) or 'root'}' (elements: {', '.join(kinds) or 'none'})"
            )
        full = (*path, element)
        flat = ".".join(full)
        roles = {
            "output": "source",
            "calculatedParameter": "source",
            "input": "sink",
            "parameter": "sink",
        }
        if kind == "Component":
            component = self.tree.components[full]  # one that failed: no connection read
            c = component.connector(connector)
            if c is None:
                raise ScenarioError(
                    f"{what}: {_undeclared(flat, connector, component, start=start)}"
                )
            return Node(
                key=("comp", *full, connector), role=roles.get(c.kind), label=f"{flat}.{connector}"
            )
        if kind == "System":
            sub = self.tree.systems[full]
            if connector not in sub:
                raise ScenarioError(
                    f"{what}: connector '{element}.{connector}' does not exist on system "
                    f"'{flat}' (connectors: {', '.join(sub) or 'none'})"
                )
            return Node(
                key=("sys", *full, connector),
                role=roles.get(sub[connector]),
                label=f"{flat}.{connector}",
            )
        if element not in refs:
            raise ScenarioError(
                f"{what}: signal dictionary reference '{flat}' could not be resolved"
            )
        key, _ = refs[element]
        dictionary = self.tree.dictionaries[key]
        if connector not in dictionary.entries:
            raise ScenarioError(
                f"{what}: '{connector}' is not an entry of signal dictionary '{dictionary.name}' "
                f"(entries: {', '.join(dictionary.entries) or 'none'})"
            )
        return Node(key=("dict", *key, connector), role=None, label=f"{flat}.{connector}")

    def read_bindings(self, element: Element, path: tuple[str, ...], *, is_component: bool) -> None:
        bindings = child(element, "ParameterBindings")
        for b in children(bindings, "ParameterBinding") if bindings is not None else ():
            self.guard(self.read_binding, b, path, is_component)

    def read_binding(self, binding: Element, path: tuple[str, ...], is_component: bool) -> None:
        parameters = read_binding(
            binding,
            self.display,
            open_file=self.documents.open,
            enumerations=self.enumerations,
            warn=self.warnings.append,
        )
        self.tree.bindings.append(
            Binding(
                depth=len(path),
                order=len(self.tree.bindings),
                scope=path,
                is_component=is_component,
                parameters=tuple(parameters),
            )
        )


def _undeclared(flat: str, connector: str, component: Component, *, start: bool) -> str:
    """Why a connection's end names no connector of ``component``, and the fix: the name it
    probably meant, or the element that declares it."""
    names = [x.name for x in component.connectors]
    declared = f"its connectors: {', '.join(names)}" if names else "it declares none"
    close = difflib.get_close_matches(connector, names, n=1)
    if close:
        return (
            f"component '{flat}' declares no connector '{connector}' ({declared}); did you "
            f"mean '{close[0]}'?"
        )
    kind = "output" if start else "input"
    return (
        f"component '{flat}' declares no connector '{connector}' ({declared}); a "
        f'connection joins declared connectors: add <ssd:Connector name="{connector}" '
        f'kind="{kind}"/> to its <ssd:Connectors> (`coupler describe` lists the '
        f"participant's channels)"
    )


def _check_address(source: str, what: str, shown: str) -> None:
    """A remote component's source: ``grpc://HOST:PORT``, ``grpcs://HOST:PORT`` or
    ``unix:///ABSOLUTE/PATH`` (a participant on this host, over its unix socket); ``shown``:
    the source as the message quotes it (as written when it expanded variables)."""
    try:
        parse_address(source if "://" in source else "?")  # the SDK's one reading of addresses
    except ScenarioError:
        raise ScenarioError(
            f"{what}: source {shown} is not of the form grpc://HOST:PORT (grpcs:// for TLS, "
            f"unix:///ABSOLUTE/PATH for a unix socket on this host); fix it"
        ) from None
