"""Small SSD files for tests: components with their source or address and connectors, the
connections between them, the default experiment; written one element a line, so an error's
line number points at what it names.

    system = SystemStructure(
        "Chain",
        components=[
            fmu("Source", "${COUPLER_FMU_DIR}/Source2.fmu", outputs=["ramp"]),
            remote("Gain", "grpc://127.0.0.1:${GAIN_PORT}", inputs=["u"], outputs=["y"]),
        ],
        connections=[("Source.ramp", "Gain.u")],
        stop_time=20,
    )
    system.write(tmp_path / "chain.ssd")  # the path, for ``coupler run``

A connection's ends are ``"Component.connector"`` (split at the first dot). Anything the
builder does not say (enumerations, signal dictionaries, OpenMCx's dialect) is a scenario of its
own, written as the file it is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

__all__ = [
    "FMU",
    "GRPC",
    "Annotation",
    "Binding",
    "Component",
    "Connection",
    "Connector",
    "SystemStructure",
    "fmu",
    "remote",
]

FMU = "application/x-fmu-sharedlibrary"
GRPC = "application/x-coupler-grpc"

Parameter = float | int | bool | str


@dataclass(frozen=True)
class Annotation:
    """``<ssc:Annotation type=TYPE><a:ELEMENT xmlns:a=TYPE ATTRIBUTES/></ssc:Annotation>``:
    e.g. ``Annotation("org.coupler.component", "Component", {"callTimeout": "5"})``."""

    type: str
    element: str
    attributes: Mapping[str, str] = field(default_factory=dict)

    def xml(self) -> str:
        attributes = "".join(f" {k}={quoteattr(v)}" for k, v in self.attributes.items())
        return (
            f"<ssc:Annotation type={quoteattr(self.type)}><a:{self.element} "
            f"xmlns:a={quoteattr(self.type)}{attributes}/></ssc:Annotation>"
        )


@dataclass(frozen=True)
class Binding:
    """A ``<ssd:ParameterBinding>`` that reads a parameter file (``.ssv``, relative to the SSD),
    its names mapped by ``mapping`` (an ``.ssm``) when given."""

    source: str
    mapping: str = ""

    def xml(self) -> str:
        if not self.mapping:
            return f"<ssd:ParameterBinding source={quoteattr(self.source)}/>"
        return (
            f"<ssd:ParameterBinding source={quoteattr(self.source)}>"
            f"<ssd:ParameterMapping source={quoteattr(self.mapping)}/></ssd:ParameterBinding>"
        )


@dataclass(frozen=True)
class Connector:
    """One ``<ssd:Connector>``; ``type`` (Real, Integer, Boolean, String, Binary; SSP 2.0's
    names too) and ``unit`` are left out when empty: the participant declares them."""

    name: str
    kind: str
    type: str = ""
    unit: str = ""

    def xml(self) -> str:
        head = f"<ssd:Connector name={quoteattr(self.name)} kind={quoteattr(self.kind)}"
        if not self.type:
            return head + "/>"
        unit = f" unit={quoteattr(self.unit)}" if self.unit else ""
        return f"{head}><ssc:{self.type}{unit}/></ssd:Connector>"


@dataclass(frozen=True)
class Component:
    """One ``<ssd:Component>``; ``type`` "" leaves the attribute out (an FMU, SSP's default);
    ``parameters`` are bound inline (a ``bool`` as Boolean, an ``int`` as Integer, a ``float``
    as Real, a ``str`` as String), ``bindings`` from files."""

    name: str
    source: str
    type: str = ""
    connectors: Sequence[Connector] = ()
    parameters: Mapping[str, Parameter] = field(default_factory=dict)
    bindings: Sequence[Binding] = ()
    annotations: Sequence[Annotation] = ()

    def lines(self) -> list[str]:
        attributes = f"name={quoteattr(self.name)}"
        if self.type:
            attributes += f" type={quoteattr(self.type)}"
        attributes += f" source={quoteattr(self.source)}"
        inner = [
            *_block("ssd:Connectors", [c.xml() for c in self.connectors]),
            *_bindings(self.parameters, self.bindings),
            *_block("ssd:Annotations", [a.xml() for a in self.annotations]),
        ]
        if not inner:
            return [f"<ssd:Component {attributes}/>"]
        return [f"<ssd:Component {attributes}>", *_indent(inner), "</ssd:Component>"]


@dataclass(frozen=True)
class Connection:
    """``start`` -> ``end``, each ``"Component.connector"``."""

    start: str
    end: str
    annotations: Sequence[Annotation] = ()

    def lines(self) -> list[str]:
        start, start_connector = self.start.split(".", 1)
        end, end_connector = self.end.split(".", 1)
        head = (
            f"<ssd:Connection startElement={quoteattr(start)} "
            f"startConnector={quoteattr(start_connector)} endElement={quoteattr(end)} "
            f"endConnector={quoteattr(end_connector)}"
        )
        if not self.annotations:
            return [head + "/>"]
        annotations = _block("ssd:Annotations", [a.xml() for a in self.annotations])
        return [head + ">", *_indent(annotations), "</ssd:Connection>"]


@dataclass(frozen=True)
class SystemStructure:
    """An SSD: its system's components and connections, its ``units`` (a name to the exponents
    of its base unit: ``{"km": {"m": 1, "factor": 1000}}``) and its ``DefaultExperiment``
    (none when ``stop_time`` is None)."""

    name: str
    components: Sequence[Component]
    connections: Sequence[Connection | tuple[str, str]] = ()
    start_time: float = 0.0
    stop_time: float | None = 1.0
    units: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    version: str = "1.0"

    def xml(self) -> str:
        connections = [c if isinstance(c, Connection) else Connection(*c) for c in self.connections]
        system = [
            *_block("ssd:Elements", [line for c in self.components for line in c.lines()]),
            *_block("ssd:Connections", [line for c in connections for line in c.lines()]),
        ]
        units = [
            f"<ssc:Unit name={quoteattr(name)}><ssc:BaseUnit"
            + "".join(f' {k}="{_number(v)}"' for k, v in base.items())
            + "/></ssc:Unit>"
            for name, base in self.units.items()
        ]
        lines = [
            '<?xml version="1.0" encoding="UTF-8"?>',
            f"<ssd:SystemStructureDescription version={quoteattr(self.version)} "
            f"name={quoteattr(self.name)}",
            '    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"',
            '    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"',
            '    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues">',
            *_indent(
                [
                    f"<ssd:System name={quoteattr(self.name)}>",
                    *_indent(system),
                    "</ssd:System>",
                    *_block("ssd:Units", units),
                    *self._experiment(),
                ]
            ),
            "</ssd:SystemStructureDescription>",
        ]
        return "\n".join(lines) + "\n"

    def write(self, path: Path) -> Path:
        """The SSD written to ``path`` (UTF-8); ``path`` again."""
        path.write_text(self.xml(), encoding="utf-8")
        return path

    def _experiment(self) -> list[str]:
        if self.stop_time is None:
            return []
        return [
            f'<ssd:DefaultExperiment startTime="{_number(self.start_time)}" '
            f'stopTime="{_number(self.stop_time)}"/>'
        ]


def fmu(
    name: str,
    source: str | Path,
    *connectors: Connector,
    inputs: Sequence[str] = (),
    outputs: Sequence[str] = (),
    parameters: Mapping[str, Parameter] | None = None,
    bindings: Sequence[Binding] = (),
    annotations: Sequence[Annotation] = (),
) -> Component:
    """An FMU component (``source``: its path, ``${VAR}`` allowed); its connectors are
    ``connectors``, then ``inputs`` and ``outputs`` by name, without type."""
    return Component(
        name,
        str(source),
        connectors=_connectors(connectors, inputs, outputs),
        parameters=parameters or {},
        bindings=bindings,
        annotations=annotations,
    )


def remote(
    name: str,
    address: str,
    *connectors: Connector,
    inputs: Sequence[str] = (),
    outputs: Sequence[str] = (),
    parameters: Mapping[str, Parameter] | None = None,
    bindings: Sequence[Binding] = (),
    annotations: Sequence[Annotation] = (),
) -> Component:
    """A participant served over gRPC at ``address`` (``grpc://HOST:PORT``, ``grpcs://``,
    ``unix:///PATH``); connectors as ``fmu``'s."""
    return Component(
        name,
        address,
        type=GRPC,
        connectors=_connectors(connectors, inputs, outputs),
        parameters=parameters or {},
        bindings=bindings,
        annotations=annotations,
    )


def _connectors(
    given: Sequence[Connector], inputs: Sequence[str], outputs: Sequence[str]
) -> tuple[Connector, ...]:
    return (
        *given,
        *(Connector(n, "input") for n in inputs),
        *(Connector(n, "output") for n in outputs),
    )


def _bindings(parameters: Mapping[str, Parameter], files: Sequence[Binding]) -> list[str]:
    if not parameters:
        return _block("ssd:ParameterBindings", [b.xml() for b in files])
    values = [
        f"<ssv:Parameter name={quoteattr(name)}><ssv:{_kind(value)} "
        f"value={quoteattr(_text(value))}/></ssv:Parameter>"
        for name, value in parameters.items()
    ]
    return [
        "<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>",
        '  <ssv:ParameterSet version="1.0" name="parameters"><ssv:Parameters>',
        *_indent(_indent(values)),
        "  </ssv:Parameters></ssv:ParameterSet>",
        "</ssd:ParameterValues></ssd:ParameterBinding>",
        *(b.xml() for b in files),
        "</ssd:ParameterBindings>",
    ]


def _kind(value: Parameter) -> str:
    if isinstance(value, bool):
        return "Boolean"
    if isinstance(value, int):
        return "Integer"
    return "Real" if isinstance(value, float) else "String"


def _text(value: Parameter) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return _number(value) if isinstance(value, int | float) else value


def _number(value: float) -> str:
    return str(value) if isinstance(value, int) else repr(float(value))


def _block(tag: str, lines: list[str]) -> list[str]:
    return [f"<{tag}>", *_indent(lines), f"</{tag}>"] if lines else []


def _indent(lines: list[str]) -> list[str]:
    return ["  " + line for line in lines]
