"""``load_ssp``: read an .ssp archive or a bare .ssd into a flattened :class:`Scenario`.

Steps: extract (archives) -> parse with the hardened parser -> schema-validate -> walk the
system tree collecting components, connectors and raw connections -> resolve connections
end to end through nested systems and signal dictionaries -> resolve parameter bindings.
Every problem found along the way is collected and raised together as a ValidationError;
everything the loader does not apply is reported in ``Scenario.warnings``.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote, urlsplit

from coupler.channels import ValueType
from coupler.errors import ScenarioError, ValidationError

from . import archive
from . import tool_annotations as notes
from .documents import (
    Element,
    boolean,
    child,
    children,
    elements,
    line_of,
    local,
    number,
    parse,
    required,
    validate,
    where,
)
from .expansion import expand
from .graph import Edge, Graph, Node
from .model import (
    FMU_TYPE,
    GRPC_TYPE,
    SUPPORTED_COMPONENT_TYPES,
    Component,
    Connector,
    DictionaryEntry,
    Enumeration,
    ParameterValue,
    Scenario,
    SignalDictionary,
    Unit,
    frozen_mapping,
)
from .parameters import BoundParameter, read_binding, read_enumerations
from .transformations import read_transformation
from .units import read_units, unit_converter

_TYPES = {
    **{t.value: t for t in ValueType},
    # SSP 2.0 names
    "Float64": ValueType.REAL,
    "Float32": ValueType.REAL,
    **{f"{s}Int{n}": ValueType.INTEGER for s in ("", "U") for n in (8, 16, 32, 64)},
}
_KINDS = ("input", "output", "parameter", "calculatedParameter", "inout")
_GRAPHICAL = {"ElementGeometry", "SystemGeometry", "GraphicalElements", "ConnectorGeometry"}


def load_ssp(
    path: str | Path,
    *,
    env: Mapping[str, str] | None = None,
    workdir: Path | None = None,
    max_archive_bytes: int = archive.MAX_EXTRACTED_BYTES,
) -> Scenario:
    """Load an .ssp archive or a bare .ssd.

    ``env`` expands ``${VAR}`` in component sources (default: ``os.environ``). Archives are
    extracted into ``workdir`` (default: a new temporary directory, which the caller owns and
    which is removed again only when loading fails).
    """
    source = Path(path).resolve()
    if not source.is_file():
        raise ScenarioError(f"{path}: no such file; give the path of an .ssp or .ssd file")
    digest = hashlib.sha256(source.read_bytes()).hexdigest()
    if source.suffix.lower() == ".ssd":
        return _Loader(source, digest, source, source.parent, env, confined=False).load()
    if source.suffix.lower() != ".ssp" and not zipfile.is_zipfile(source):
        raise ScenarioError(f"{source.name}: expected an .ssp archive or an .ssd file")
    created = workdir is None
    target = Path(tempfile.mkdtemp(prefix="coupler-ssp-")) if workdir is None else workdir
    try:
        ssd = archive.extract(source, target, max_bytes=max_archive_bytes)
        return _Loader(source, digest, ssd, target.resolve(), env, confined=True).load()
    except BaseException:
        if created:
            archive.remove(target)
        raise


@dataclass
class _Binding:
    depth: int
    order: int
    scope: tuple[str, ...]
    is_component: bool
    parameters: list[BoundParameter]


@dataclass
class _State:
    components: dict[tuple[str, ...], Component] = field(default_factory=dict)
    systems: dict[tuple[str, ...], dict[str, str]] = field(default_factory=dict)
    """System path -> its own connectors (name -> kind)."""
    dictionaries: dict[tuple[str, ...], SignalDictionary] = field(default_factory=dict)
    """System path + dictionary name -> dictionary."""
    bindings: list[_Binding] = field(default_factory=list)
    graph: Graph = field(default_factory=Graph)


class _Loader:
    def __init__(
        self,
        source: Path,
        digest: str,
        ssd: Path,
        resource_dir: Path,
        env: Mapping[str, str] | None,
        *,
        confined: bool,
    ) -> None:
        self.source = source
        self.digest = digest
        self.ssd = ssd
        self.resource_dir = resource_dir
        self.env = os.environ if env is None else env
        self.confined = confined
        self.display = ssd.name
        self.warnings: list[str] = []
        self.problems: list[str] = []
        self.units: dict[str, Unit] = {}
        self.enumerations: dict[str, Enumeration] = {}
        self.state = _State()

    # -- files -----------------------------------------------------------------------------

    def open_file(self, source: str, element: Element, display: str) -> tuple[Element, str]:
        """Parse and validate a file referenced from ``element`` (ssv, ssm, ssb)."""
        path = self.resolve(source, element, display, what="file")
        name = (
            path.relative_to(self.resource_dir).as_posix()
            if path.is_relative_to(self.resource_dir)
            else str(path)
        )
        if not path.is_file():
            raise ScenarioError(
                f"{where(display, element)}: referenced file '{source}' does not exist "
                f"(looked for {path}); add it or fix the source attribute"
            )
        root = parse(path, name)
        self.note(validate(root, name))
        self.warnings.extend(notes.unsupported(root, name))
        return root, name

    def resolve(self, source: str, element: Element, display: str, *, what: str) -> Path:
        """An SSD-relative URI as an absolute path, confined to the archive for .ssp files."""
        parts = urlsplit(source)
        if parts.scheme and parts.scheme != "file" and len(parts.scheme) > 1:
            raise ScenarioError(
                f"{where(display, element)}: {what} source '{source}' uses the scheme "
                f"'{parts.scheme}:', which is not supported; use a path relative to the SSD"
            )
        raw = unquote(parts.path if parts.scheme == "file" else source)
        path = (self.resource_dir / raw).resolve()
        if self.confined and not path.is_relative_to(self.resource_dir):
            raise ScenarioError(
                f"{where(display, element)}: {what} source '{source}' points outside the .ssp "
                "archive; use a path inside the archive"
            )
        return path

    def note(self, warning: str | None) -> None:
        if warning:
            self.warnings.append(warning)

    # -- top level -------------------------------------------------------------------------

    def load(self) -> Scenario:
        root = parse(self.ssd, self.display)
        if local(root) != "SystemStructureDescription":
            raise ScenarioError(
                f"{self.display} line {root.sourceline}: root element is <{local(root)}>, "
                "expected <ssd:SystemStructureDescription>"
            )
        self.note(validate(root, self.display))
        version = required(root, "version", self.display)
        if not (version.startswith("1.") or version.startswith("2.")):
            self.warnings.append(
                f"{self.display}: SSP version '{version}' is neither 1.x nor 2.x; loaded as SSP 1.0"
            )
        self.warnings.extend(notes.unsupported(root, self.display))
        self.units = read_units(child(root, "Units"), self.display)
        self.enumerations = read_enumerations(child(root, "Enumerations"), self.display)
        system = child(root, "System")
        if system is None:
            raise ScenarioError(f"{self.display} line {root.sourceline}: no <ssd:System>; add one")
        self.walk(system, ())
        connections = self.state.graph.flatten(self.state.components, self.warnings, self.problems)
        components = self.apply_parameters()
        start, stop, task, results = None, None, None, None
        experiment = child(root, "DefaultExperiment")
        if experiment is not None:
            start = number(experiment, "startTime", self.display, None)
            stop = number(experiment, "stopTime", self.display, None)
            task = notes.read_task(experiment, self.display, self.warnings)
            results = notes.read_results(experiment, self.display, self.warnings)
        if self.problems:
            raise ValidationError(self.problems, subject=self.display)
        return Scenario(
            source=self.source,
            sha256=self.digest,
            ssp_version=version,
            name=root.get("name", ""),
            components=components,
            connections=tuple(connections),
            units=frozen_mapping(self.units),
            enumerations=frozen_mapping(self.enumerations),
            signal_dictionaries=frozen_mapping(
                {".".join(k): v for k, v in self.state.dictionaries.items()}
            ),
            start_time=start,
            stop_time=stop,
            step_size=task.delta_time if task else None,
            step_type=task.step_type if task else None,
            task=task,
            results=results,
            warnings=tuple(self.warnings),
            resource_dir=self.resource_dir,
        )

    # -- the system tree -------------------------------------------------------------------

    def walk(self, system: Element, path: tuple[str, ...]) -> None:
        """Collect components, connectors, dictionaries, bindings and raw connections."""
        own = {}
        connectors = child(system, "Connectors")
        for c in children(connectors, "Connector") if connectors is not None else ():
            own[required(c, "name", self.display)] = c.get("kind", "")
        self.state.systems[path] = own
        dictionaries = child(system, "SignalDictionaries")
        for d in children(dictionaries, "SignalDictionary") if dictionaries is not None else ():
            self.guard(self.read_dictionary, d, path)
        elements_ = child(system, "Elements")
        kinds: dict[str, str] = {}
        refs: dict[str, tuple[tuple[str, ...], Element]] = {}
        for element in elements(elements_) if elements_ is not None else ():
            kind = local(element)
            name = element.get("name", "")
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
            raise ScenarioError(
                f"{here}: component '{name}' has type '{mime}', which is not supported; "
                f"use {FMU_TYPE} or {GRPC_TYPE}"
            )
        what = f"{here}: component '{name}'"
        source = expand(required(element, "source", self.display), self.env, what=what)
        if mime == FMU_TYPE:
            fmu = self.resolve(source, element, self.display, what="FMU")
            if not fmu.is_file():
                raise ScenarioError(
                    f"{what}: FMU file '{source}' does not exist (looked for {fmu}); add the FMU "
                    "to the archive/directory or fix the source attribute"
                )
            source = str(fmu)
        else:
            parts = urlsplit(source)
            try:
                port = parts.port
            except ValueError:
                port = None
            if parts.scheme not in ("grpc", "grpcs") or not parts.hostname or port is None:
                raise ScenarioError(
                    f"{what}: source '{source}' is not of the form grpc://HOST:PORT (or "
                    f"grpcs:// for TLS); fix it"
                )
        implementation = element.get("implementation", "any")
        if implementation == "ModelExchange":
            self.warnings.append(
                f"{here}: component '{name}' asks for implementation=\"ModelExchange\", which is "
                "not supported; it runs as co-simulation"
            )
        self.state.components[path] = Component(
            name=name,
            type=mime,
            source=source,
            connectors=self.read_connectors(element, name),
            implementation=implementation,
            delta_time=notes.component_delta_time(element, self.display, self.warnings),
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
        result = []
        connectors = child(element, "Connectors")
        for c in children(connectors, "Connector") if connectors is not None else ():
            name = required(c, "name", self.display)
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
                    if local(e) in _TYPES
                    or local(e) not in ("ConnectorGeometry", "Annotations", "Dimension")
                ),
                None,
            )
            type_ = None
            unit = enumeration = mime = None
            if typed is not None:
                tag = local(typed)
                if tag not in _TYPES:
                    raise ScenarioError(
                        f"{where(self.display, typed)}: connector '{owner}.{name}' has type "
                        f"<{tag}>, which is not supported; use Real, Integer, Boolean, String, "
                        "Enumeration or Binary"
                    )
                type_ = _TYPES[tag]
                unit = typed.get("unit")
                if unit is not None and unit not in self.units:
                    raise ScenarioError(
                        f"{where(self.display, typed)}: connector '{owner}.{name}' uses unit "
                        f"'{unit}', which is not defined in <Units> (units: "
                        f"{', '.join(self.units) or 'none'}); define it"
                    )
                if type_ is ValueType.ENUMERATION:
                    enumeration = typed.get("name")
                    if enumeration not in self.enumerations:
                        raise ScenarioError(
                            f"{where(self.display, typed)}: connector '{owner}.{name}' uses "
                            f"enumeration '{enumeration}', which is not defined in <Enumerations>"
                        )
                if type_ is ValueType.BINARY:
                    mime = typed.get("mime-type", "application/octet-stream")
            result.append(
                Connector(
                    name=name,
                    kind=kind,
                    type=type_,
                    unit=unit,
                    enumeration=enumeration,
                    mime_type=mime,
                    line=line_of(c),
                )
            )
        return tuple(result)

    # -- signal dictionaries ---------------------------------------------------------------

    def read_dictionary(self, element: Element, path: tuple[str, ...]) -> None:
        name = required(element, "name", self.display)
        source = element.get("source")
        if source:
            root, display = self.open_file(source, element, self.display)
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
            typed = next((e for e in elements(entry) if local(e) in _TYPES), None)
            entries[entry_name] = DictionaryEntry(
                name=entry_name,
                type=_TYPES[local(typed)] if typed is not None else None,
                unit=typed.get("unit") if typed is not None else None,
            )
        self.state.dictionaries[(*path, name)] = SignalDictionary(
            name=name, entries=entries, file=display, line=line_of(element)
        )

    def find_dictionary(self, element: Element, path: tuple[str, ...]) -> tuple[str, ...] | None:
        """The key of the dictionary a reference names, looked up from ``path`` upwards."""
        name = element.get("dictionary", "")
        for depth in range(len(path), -1, -1):
            key = (*path[:depth], name)
            if key in self.state.dictionaries:
                return key
        self.problems.append(
            f"{where(self.display, element)}: SignalDictionaryReference "
            f"'{element.get('name', '')}' names dictionary '{name}', which is not defined in "
            "this system or an enclosing one; add it to <SignalDictionaries>"
        )
        return None

    # -- connections -----------------------------------------------------------------------

    def read_connection(
        self,
        element: Element,
        path: tuple[str, ...],
        kinds: dict[str, str],
        refs: dict[str, tuple[tuple[str, ...], Element]],
    ) -> None:
        start_el, end_el = element.get("startElement"), element.get("endElement")
        start_c = required(element, "startConnector", self.display)
        end_c = required(element, "endConnector", self.display)
        start = f"{start_el}.{start_c}" if start_el else start_c
        label = f"{start} -> {f'{end_el}.{end_c}' if end_el else end_c}"
        what = f"{where(self.display, element)}: connection {label}"
        a = self.endpoint(what, path, start_el, start_c, kinds, refs)
        b = self.endpoint(what, path, end_el, end_c, kinds, refs)
        decoupled, decouple_type, priority = notes.decoupling(element, self.display)
        edge = Edge(
            transformation=read_transformation(element, self.display),
            suppress_unit_conversion=boolean(
                element, "suppressUnitConversion", self.display, False
            ),
            decoupled=decoupled,
            decouple_type=decouple_type,
            decouple_priority=priority,
            file=self.display,
            line=line_of(element),
            label=label,
        )
        self.state.graph.add(a, b, edge)

    def endpoint(
        self,
        what: str,
        path: tuple[str, ...],
        element: str | None,
        connector: str,
        kinds: dict[str, str],
        refs: dict[str, tuple[tuple[str, ...], Element]],
    ) -> Node:
        """The graph node of one end of a connection, with its role seen from the system."""
        if not element:
            own = self.state.systems[path]
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
            component = self.state.components.get(full)
            if component is None:  # already reported as a problem
                raise ScenarioError(f"{what}: component '{flat}' could not be loaded (see above)")
            c = component.connector(connector)
            if c is None:
                raise ScenarioError(
                    f"{what}: connector '{element}.{connector}' does not exist in component "
                    f"'{flat}' (connectors: "
                    f"{', '.join(x.name for x in component.connectors) or 'none'})"
                )
            return Node(
                key=("comp", *full, connector), role=roles.get(c.kind), label=f"{flat}.{connector}"
            )
        if kind == "System":
            sub = self.state.systems[full]
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
        dictionary = self.state.dictionaries[key]
        if connector not in dictionary.entries:
            raise ScenarioError(
                f"{what}: '{connector}' is not an entry of signal dictionary '{dictionary.name}' "
                f"(entries: {', '.join(dictionary.entries) or 'none'})"
            )
        return Node(key=("dict", *key, connector), role=None, label=f"{flat}.{connector}")

    # -- parameters ------------------------------------------------------------------------

    def read_bindings(self, element: Element, path: tuple[str, ...], *, is_component: bool) -> None:
        bindings = child(element, "ParameterBindings")
        for b in children(bindings, "ParameterBinding") if bindings is not None else ():
            try:
                parameters = read_binding(
                    b,
                    self.display,
                    open_file=self.open_file,
                    enumerations=self.enumerations,
                    warn=self.warnings.append,
                )
            except ValidationError as exc:
                self.problems.extend(exc.problems)
                continue
            except ScenarioError as exc:
                self.problems.append(str(exc))
                continue
            self.state.bindings.append(
                _Binding(
                    depth=len(path),
                    order=len(self.state.bindings),
                    scope=path,
                    is_component=is_component,
                    parameters=parameters,
                )
            )

    def apply_parameters(self) -> tuple[Component, ...]:
        """Components with their parameters; deeper bindings first, so higher levels win."""
        values: dict[tuple[str, ...], dict[str, ParameterValue]] = {
            p: {} for p in self.state.components
        }
        for binding in sorted(self.state.bindings, key=lambda b: (-b.depth, b.order)):
            for parameter in binding.parameters:
                target = self.target(binding, parameter)
                if target is None:
                    continue
                path, name = target
                try:
                    values[path][name] = self.fit(self.state.components[path], name, parameter)
                except ScenarioError as exc:
                    self.problems.append(str(exc))
        return tuple(
            Component(**{**c.__dict__, "parameters": frozen_mapping(values[p])})
            for p, c in self.state.components.items()
        )

    def target(
        self, binding: _Binding, parameter: BoundParameter
    ) -> tuple[tuple[str, ...], str] | None:
        if binding.is_component:
            return binding.scope, parameter.name
        parts = tuple(parameter.name.split("."))
        for i in range(len(parts) - 1, 0, -1):
            candidate = binding.scope + parts[:i]
            if candidate in self.state.components:
                return candidate, ".".join(parts[i:])
        system = ".".join(binding.scope) or "the root system"
        if parameter.name in self.state.systems.get(binding.scope, {}):
            self.warnings.append(
                f"{parameter.value.origin}: parameter '{parameter.name}' binds a connector of "
                f"{system}; system-connector parameters are not propagated, ignored - bind the "
                "component's parameter instead"
            )
        else:
            self.warnings.append(
                f"{parameter.value.origin}: parameter '{parameter.name}' matches no component in "
                f"{system}; ignored (use Component.parameter names or a prefix)"
            )
        return None

    def fit(self, component: Component, name: str, parameter: BoundParameter) -> ParameterValue:
        """The value converted to the connector's type and unit, when the SSD declares one."""
        value = parameter.value
        connector = component.connector(name)
        if connector is None or connector.type is None:
            return value
        what = f"{value.origin}: parameter '{component.name}.{name}'"
        if connector.type is not value.type:
            if connector.type is ValueType.REAL and value.type is ValueType.INTEGER:
                value = ParameterValue(
                    value=float(value.value),
                    type=ValueType.REAL,
                    unit=value.unit,
                    origin=value.origin,
                )
            else:
                raise ScenarioError(
                    f"{what} is {value.type} but the connector is {connector.type}; "
                    f"give a {connector.type} value"
                )
        if (
            connector.unit
            and value.unit
            and connector.unit != value.unit
            and not parameter.suppress_unit_conversion
        ):
            convert = unit_converter(
                {**self.units, **parameter.units}, value.unit, connector.unit, what=what
            )
            if convert is not None:
                return ParameterValue(
                    value=convert(float(value.value)),
                    type=value.type,
                    unit=connector.unit,
                    origin=value.origin,
                )
        return value
