"""The parsed SSP as a typed, frozen object model; field names follow SSP 1.0.

Only what the loader resolved lives here (flattened components and connections, units,
parameters, run settings). Run-time state lives elsewhere.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import TypeVar

from coupler.channels import Causality, Value, ValueType

K = TypeVar("K")
V = TypeVar("V")

FMU_TYPE = "application/x-fmu-sharedlibrary"
GRPC_TYPE = "application/x-coupler-grpc"
CONSTANT_TYPE = "application/avl-mcx-constant"
INTEGRATOR_TYPE = "application/avl-mcx-integrator"
VECTOR_INTEGRATOR_TYPE = "application/avl-mcx-vector-integrator"
BUILTIN_TYPES = (CONSTANT_TYPE, INTEGRATOR_TYPE, VECTOR_INTEGRATOR_TYPE)
"""OpenMCx's built-in components, run in the orchestrator's process (docs/openmcx.md)."""
SUPPORTED_COMPONENT_TYPES = (FMU_TYPE, GRPC_TYPE, *BUILTIN_TYPES)
REPLAY_SCHEME = "replay:"
"""A source ``replay:PATH#Component`` (either type): a recording stands in (docs/replay.md)."""


def frozen_mapping(items: Mapping[K, V] | None = None) -> Mapping[K, V]:
    """A read-only copy of ``items``."""
    return MappingProxyType(dict(items or {}))


@dataclass(frozen=True, kw_only=True)
class BaseUnit:
    """SI exponents plus factor and offset: value_in_base = factor * value + offset."""

    kg: int = 0
    m: int = 0
    s: int = 0
    A: int = 0
    K: int = 0
    mol: int = 0
    cd: int = 0
    rad: int = 0
    factor: float = 1.0
    offset: float = 0.0

    @property
    def exponents(self) -> tuple[int, ...]:
        """The SI exponents, in SSP order (kg, m, s, A, K, mol, cd, rad)."""
        return (self.kg, self.m, self.s, self.A, self.K, self.mol, self.cd, self.rad)

    def dimension(self) -> str:
        """The exponents as text, e.g. ``m s-1``; ``1`` when dimensionless."""
        names = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
        parts = [
            n if e == 1 else f"{n}{e}" for n, e in zip(names, self.exponents, strict=True) if e
        ]
        return " ".join(parts) or "1"


@dataclass(frozen=True, kw_only=True)
class Unit:
    """An ``ssc:Unit`` of the SSD (or of an .ssv/.ssb file)."""

    name: str
    base_unit: BaseUnit
    file: str = ""
    line: int = 0


@dataclass(frozen=True, kw_only=True)
class Enumeration:
    """An ``ssc:Enumeration``: item names and their integer values."""

    name: str
    items: Mapping[str, int]


@dataclass(frozen=True, kw_only=True)
class Port:
    """OpenMCx's settings of one port (annotation ``com.avl.model.connect.ssp.port``): of a
    scalar connector, or of one element of a vector connector."""

    default: Value | None = None
    """An input's value when nothing is connected to it (through scale, offset, min, max)."""
    initial: Value | None = None
    """The value a decoupled connection carries during initialization (input's, else the
    output's, else 0)."""
    min: float | None = None
    """Lower clamp (Real and Integer ports)."""
    max: float | None = None
    """Upper clamp."""
    scale: float | None = None
    """Inputs: ``x * scale + offset`` after unit conversion, then clamped; outputs: clamped,
    then ``x * scale + offset``."""
    offset: float | None = None
    """See ``scale``."""
    write_results: bool = True
    """False: no column in the OpenMCx result files."""

    @property
    def transforms(self) -> bool:
        """Whether values change on their way through the port."""
        return any(v is not None for v in (self.min, self.max, self.scale, self.offset))


@dataclass(frozen=True, kw_only=True)
class Connector:
    """A connector of a component, as declared in the SSD (an OpenMCx vector connector is one
    ``Connector`` per element, ``v[1]``, ``v[2]``, ...)."""

    name: str
    kind: str
    """SSP kind: input, output, parameter, calculatedParameter or inout."""
    type: ValueType | None
    """Connector type; None when the SSD leaves it to the component (FMU variable)."""
    unit: str | None = None
    """Unit name (Real connectors), referring to the scenario's units."""
    enumeration: str | None = None
    """Enumeration name (Enumeration connectors)."""
    mime_type: str | None = None
    """MIME type (Binary connectors)."""
    name_in_model: str | None = None
    """The participant's channel it stands for when it differs from ``name`` (OpenMCx
    ``nameInModel``; for a vector element ``nameInModel[i]``)."""
    port: Port | None = None
    """OpenMCx port settings, when the SSD gives any."""
    vector: str | None = None
    """The OpenMCx vector connector this element belongs to (``v`` of ``v[2]``)."""
    line: int = 0

    @property
    def channel(self) -> str:
        """The participant's channel this connector is."""
        return self.name_in_model or self.name

    @property
    def causality(self) -> Causality | None:
        """The channel causality; None for inout, which has no Coupler equivalent."""
        return {
            "input": Causality.INPUT,
            "output": Causality.OUTPUT,
            "parameter": Causality.PARAMETER,
            "calculatedParameter": Causality.OUTPUT,
        }.get(self.kind)


@dataclass(frozen=True, kw_only=True)
class ParameterValue:
    """A resolved parameter value with its type and unit, and where it came from."""

    value: Value
    type: ValueType
    unit: str | None = None
    origin: str = ""
    """``file line N`` of the ssv:Parameter (or the mapping entry) that set it."""


@dataclass(frozen=True, kw_only=True)
class ComponentSettings:
    """Coupler's own settings of one component (annotation ``org.coupler.component``); None
    leaves the command line's (or the default) choice."""

    isolate: bool | None = None
    """FMUs: run in a child process (the generic FMU host), so a crash or hang of the FMU is a
    participant fault, not the orchestrator's."""
    call_timeout: float | None = None
    """Deadline of every call to this participant [s]."""
    tls_ca: Path | None = None
    """CA bundle trusted for this participant (``grpcs://``)."""
    tls_cert: Path | None = None
    """Client certificate presented to it (mutual TLS)."""
    tls_key: Path | None = None
    """Key of ``tls_cert``."""
    token_file: Path | None = None
    """File holding the bearer token sent to it."""


@dataclass(frozen=True, kw_only=True)
class Constant:
    """OpenMCx built-in Constant: one value per output element, in connector order."""

    values: tuple[Value, ...]


@dataclass(frozen=True, kw_only=True)
class Integrator:
    """OpenMCx built-in Integrator: explicit Euler, ``y += gain * u * h / sub_steps`` per
    sub-step, the input read again at each sub-step's start."""

    gain: float = 1.0
    initial_state: float = 0.0
    sub_steps: int = 1


@dataclass(frozen=True, kw_only=True)
class VectorIntegrator:
    """OpenMCx built-in VectorIntegrator: input element i (all inputs flattened in connector
    order) integrates into output element i, ``y_i += u_i * h``."""

    initial_state: float = 0.0


Builtin = Constant | Integrator | VectorIntegrator


@dataclass(frozen=True, kw_only=True)
class Component:
    """A component of the flattened system."""

    name: str
    """Name relative to the root system, nested names joined with '.' (``Sub.Gain``)."""
    type: str
    """MIME type: ``application/x-fmu-sharedlibrary``, ``application/x-coupler-grpc`` or one of
    OpenMCx's built-ins (``BUILTIN_TYPES``)."""
    source: str
    """For FMUs an absolute path; for gRPC ``grpc://HOST:PORT`` (``grpcs://``, or
    ``unix:///PATH``) with ``${VAR}`` expanded; for a replay ``replay:PATH#Component`` with
    PATH absolute."""
    connectors: tuple[Connector, ...]
    parameters: Mapping[str, ParameterValue] = field(default_factory=lambda: frozen_mapping())
    """Parameter values by connector/variable name, after all bindings and mappings."""
    implementation: str = "any"
    delta_time: float | None = None
    """Per-component communication step (OpenMCx ``com.avl.model.connect.ssp.component``)."""
    input_at_end_time: bool = False
    """OpenMCx: inputs are read at the end of each of its steps (through the connections'
    inter/extrapolation), not at the start."""
    trigger_sequence: int = -1
    """OpenMCx: in a loop, a connection from a component with a higher trigger sequence to
    one with a lower is cut first."""
    builtin: Builtin | None = None
    """The specific data of an OpenMCx built-in component."""
    settings: ComponentSettings = field(default_factory=ComponentSettings)
    """Coupler's own settings (``org.coupler.component``)."""
    file: str = ""
    line: int = 0

    def connector(self, name: str) -> Connector | None:
        """The connector called ``name``, or None."""
        return self._by_name.get(name)

    @cached_property
    def _by_name(self) -> dict[str, Connector]:
        by_name: dict[str, Connector] = {}
        for c in self.connectors:
            by_name.setdefault(c.name, c)
        return by_name


@dataclass(frozen=True, kw_only=True)
class LinearTransformation:
    """``ssc:LinearTransformation``: target = factor * source + offset."""

    factor: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True, kw_only=True)
class BooleanMappingTransformation:
    """``ssc:BooleanMappingTransformation``; unmapped values pass unchanged."""

    mapping: Mapping[bool, bool]


@dataclass(frozen=True, kw_only=True)
class IntegerMappingTransformation:
    """``ssc:IntegerMappingTransformation``; unmapped values pass unchanged."""

    mapping: Mapping[int, int]


@dataclass(frozen=True, kw_only=True)
class EnumerationMappingTransformation:
    """``ssc:EnumerationMappingTransformation`` by item name; unmapped names pass unchanged."""

    mapping: Mapping[str, str]


@dataclass(frozen=True, kw_only=True)
class InterExtrapolation:
    """OpenMCx ``com.avl.model.connect.ssp.connection.inter_extrapolation`` of a connection."""

    extrapolation_order: int
    """0 (``zero``) or 1 (``first``)."""
    interpolation_order: int
    """0 (``zero``) or 1 (``first``)."""


Transformation = (
    LinearTransformation
    | BooleanMappingTransformation
    | IntegerMappingTransformation
    | EnumerationMappingTransformation
)


@dataclass(frozen=True, kw_only=True)
class Connection:
    """A connection between two component connectors, resolved through nested systems."""

    start_element: str
    start_connector: str
    end_element: str
    end_connector: str
    transformation: Transformation | None = None
    suppress_unit_conversion: bool = False
    decoupled: bool = False
    """True when the connection may be cut for ordering (OpenMCx Always, or Coupler's own)."""
    decouple_type: str | None = None
    """OpenMCx decoupling: ``never``, ``always`` or ``if_needed``; None when not given."""
    decouple_priority: int | None = None
    """OpenMCx ``IfNeeded priority``."""
    inter_extrapolation: InterExtrapolation | None = None
    """OpenMCx inter/extrapolation of the values the target reads; None when not given."""
    file: str = ""
    line: int = 0

    @property
    def start(self) -> str:
        """``element.connector`` of the start."""
        return f"{self.start_element}.{self.start_connector}"

    @property
    def end(self) -> str:
        """``element.connector`` of the end."""
        return f"{self.end_element}.{self.end_connector}"


@dataclass(frozen=True, kw_only=True)
class DictionaryEntry:
    """An ``ssb:DictionaryEntry``."""

    name: str
    type: ValueType | None
    unit: str | None = None


@dataclass(frozen=True, kw_only=True)
class SignalDictionary:
    """A signal dictionary of a system (inline or an .ssb file)."""

    name: str
    entries: Mapping[str, DictionaryEntry]
    file: str = ""
    line: int = 0


@dataclass(frozen=True, kw_only=True)
class Task:
    """OpenMCx ``com.avl.model.connect.ssp.task`` settings (Task element of DefaultExperiment)."""

    step_type: str
    """sequential, parallel_single_thread, parallel_one_step_size or parallel_sync_all."""
    delta_time: float = 0.01
    end_type: str = "end_time"
    """end_time or first_component."""
    sum_time: bool = False
    input_at_end_time: bool = False
    relative_eps: float = 1e-10
    timing_output: bool = False


@dataclass(frozen=True, kw_only=True)
class Backend:
    """One OpenMCx results backend."""

    type: str
    store_at_runtime: bool = True


@dataclass(frozen=True, kw_only=True)
class Results:
    """OpenMCx ``com.avl.model.connect.ssp.results`` settings."""

    output_directory: str | None = None
    result_level: str = "synchronization"
    backends: tuple[Backend, ...] = ()


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """A loaded, flattened SSP."""

    source: Path
    """The .ssp or .ssd file loaded."""
    sha256: str
    """Hex digest of that file."""
    ssp_version: str
    name: str
    components: tuple[Component, ...]
    connections: tuple[Connection, ...]
    units: Mapping[str, Unit]
    enumerations: Mapping[str, Enumeration]
    signal_dictionaries: Mapping[str, SignalDictionary]
    """By system path and name, e.g. ``Bus`` or ``Sub.Bus``."""
    start_time: float | None
    stop_time: float | None
    step_size: float | None
    """OpenMCx task deltaTime, when given."""
    step_type: str | None
    task: Task | None
    results: Results | None
    warnings: tuple[str, ...]
    resource_dir: Path
    """Where component sources and parameter files resolve."""
    openmcx: str = ""
    """Why the scenario runs with OpenMCx's semantics (``file line N: ...``, the first element
    only OpenMCx defines); empty: Coupler's (docs/openmcx.md)."""

    def component(self, name: str) -> Component | None:
        """The component called ``name`` (flattened name), or None."""
        return next((c for c in self.components if c.name == name), None)

    def connector(self, element: str, connector: str) -> Connector | None:
        """The connector ``element.connector``, or None."""
        component = self.component(element)
        return component.connector(connector) if component else None
