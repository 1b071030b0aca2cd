"""From a loaded scenario to a plan: create the participants and check them against the SSD.

Every remote participant (and every FMU, which looks the same) is described and checked
against its SSD component before anything runs: each connector exists with the same causality,
type and unit; every input is connected or has a start value; connected channels have
compatible types. All problems are reported together in one ValidationError.
"""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from coupler.channels import (
    Causality,
    Channel,
    Description,
    Value,
    ValueType,
    fits_fixed_step,
)
from coupler.client import RemoteParticipant
from coupler.errors import CouplerError, ScenarioError, ValidationError
from coupler.fmu import FmuParticipant
from coupler.participant import Participant
from coupler.security import ClientSecurity
from coupler_orchestrator import ssp
from coupler_orchestrator.master import gauss_seidel_order
from coupler_orchestrator.plan import Algorithm, Converter, Link, Member, Plan, TimeGrid

#: Connected types that are compatible without a transformation: (output, input).
_COMPATIBLE = {
    (ValueType.INTEGER, ValueType.REAL),
    (ValueType.INTEGER, ValueType.ENUMERATION),
    (ValueType.ENUMERATION, ValueType.INTEGER),
}


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """What the user may set on top of the scenario (the CLI flags of ``coupler run``)."""

    start_time: float | None = None
    """Overrides DefaultExperiment startTime [s]; default 0."""
    stop_time: float | None = None
    """Overrides DefaultExperiment stopTime [s]."""
    step_size: float | None = None
    """Base communication step [s]; default the OpenMCx task deltaTime."""
    algorithm: Algorithm | None = None
    """Master algorithm; default from the OpenMCx task stepType, else Jacobi."""
    realtime_factor: float | None = None
    """Pace the run; None runs as fast as possible."""
    parameters: Mapping[str, str] = field(default_factory=dict)
    """``Component.name`` -> value text, overriding the SSD's parameter bindings."""
    run_id: str = field(default_factory=lambda: uuid.uuid4().hex)
    """Identifies the run; a random UUID unless given."""
    lease: float | None = None
    """Lease of the run at each participant [s]; default: well above the call deadline and the
    pacing (``lease_of``)."""
    connect_timeout: float = 10.0
    """How long a remote participant may take to report SERVING [s]."""
    call_timeout: float = 30.0
    """Deadline of each call to a remote participant [s]."""
    security: ClientSecurity = field(default_factory=ClientSecurity.from_environment)
    """TLS trust, client certificate and token for every remote participant (default: the
    ``COUPLER_TLS_*`` and ``COUPLER_TOKEN_FILE`` environment variables)."""


def create_participant(component: ssp.Component, options: RunOptions) -> Participant:
    """The participant behind a component: an FMU in-process, or a remote one."""
    if component.type == ssp.FMU_TYPE:
        return FmuParticipant(Path(component.source), name=component.name)
    if component.type == ssp.GRPC_TYPE:
        return RemoteParticipant(
            component.source,
            name=component.name,
            connect_timeout=options.connect_timeout,
            call_timeout=options.call_timeout,
            security=options.security,
        )
    raise ScenarioError(
        f"{_where(component)}: component '{component.name}' has type '{component.type}'; "
        f"supported: {ssp.FMU_TYPE}, {ssp.GRPC_TYPE}"
    )


def _where(item: ssp.Component | ssp.Connection | ssp.Connector, file: str = "") -> str:
    name = Path(getattr(item, "file", "") or file).name or "scenario"
    return f"{name} line {item.line}"


async def describe_all(
    scenario: ssp.Scenario, options: RunOptions
) -> tuple[dict[str, Participant], dict[str, Description], list[str]]:
    """Open and describe every component's participant concurrently; problems are collected."""
    participants: dict[str, Participant] = {}
    problems: list[str] = []
    for component in scenario.components:
        try:
            participants[component.name] = create_participant(component, options)
        except CouplerError as exc:
            problems.append(str(exc))

    async def describe(name: str, participant: Participant) -> Description:
        await participant.open()
        return await participant.describe()

    names = list(participants)
    results = await asyncio.gather(
        *(describe(n, participants[n]) for n in names), return_exceptions=True
    )
    descriptions: dict[str, Description] = {}
    for name, result in zip(names, results, strict=True):
        component = scenario.component(name)
        assert component is not None
        if isinstance(result, CouplerError):
            problems.append(f"{_where(component)}: component '{name}': {result}")
        elif isinstance(result, BaseException):
            problems.append(
                f"{_where(component)}: component '{name}': {type(result).__name__}: {result}"
            )
        else:
            descriptions[name] = result
    return participants, descriptions, problems


def check_participants(
    scenario: ssp.Scenario, descriptions: Mapping[str, Description]
) -> list[str]:
    """Every mismatch between the SSD and what the participants declare."""
    problems: list[str] = []
    connected_inputs = {(c.end_element, c.end_connector) for c in scenario.connections}
    for component in scenario.components:
        description = descriptions.get(component.name)
        if description is None:
            continue
        for connector in component.connectors:
            problems.extend(_check_connector(component, connector, description))
        for channel in description.of(Causality.INPUT):
            driven = (component.name, channel.name) in connected_inputs
            if not driven and channel.start is None and channel.name not in component.parameters:
                problems.append(
                    f"{_where(component)}: input '{component.name}.{channel.name}' is neither "
                    f"connected nor has a start value; connect it or bind a value to it"
                )
    for connection in scenario.connections:
        problems.extend(_check_link_types(connection, descriptions))
    return problems


def _check_connector(
    component: ssp.Component, connector: ssp.Connector, description: Description
) -> list[str]:
    where = f"{_where(connector, component.file)}: connector '{component.name}.{connector.name}'"
    channel = description.channel(connector.name)
    if channel is None:
        names = ", ".join(c.name for c in description.channels) or "none"
        return [
            f"{where} does not exist on participant '{description.name}' (its channels: "
            f"{names}); rename the connector or the channel"
        ]
    problems = []
    if connector.causality is not None and connector.causality is not channel.causality:
        problems.append(
            f"{where} is {connector.kind} in the SSD but the participant declares it "
            f"{channel.causality}; change the connector's kind to {channel.causality}"
        )
    if connector.type is not None and connector.type is not channel.type:
        problems.append(
            f"{where} expects {connector.type}, but the participant declares {channel.type}; "
            f"declare the connector <ssc:{channel.type}/>"
        )
    if connector.unit and channel.unit and connector.unit != channel.unit:
        problems.append(
            f"{where} has unit '{connector.unit}' in the SSD but the participant declares "
            f"'{channel.unit}'; declare the participant's unit (connections convert units)"
        )
    return problems


def _check_link_types(
    connection: ssp.Connection, descriptions: Mapping[str, Description]
) -> list[str]:
    start = _channel(descriptions, connection.start_element, connection.start_connector)
    end = _channel(descriptions, connection.end_element, connection.end_connector)
    if start is None or end is None or connection.transformation is not None:
        return []
    if start.type is end.type or (start.type, end.type) in _COMPATIBLE:
        return []
    return [
        f"{_where(connection)}: connector '{connection.end}' expects {end.type}, but "
        f"'{connection.start}' is {start.type}; connect compatible channels or add a "
        f"transformation"
    ]


def _channel(descriptions: Mapping[str, Description], element: str, name: str) -> Channel | None:
    description = descriptions.get(element)
    return description.channel(name) if description else None


def parse_overrides(
    overrides: Mapping[str, str], descriptions: Mapping[str, Description]
) -> tuple[dict[str, dict[str, Value]], list[str]]:
    """``--param Component.name=value`` texts as typed values per component."""
    values: dict[str, dict[str, Value]] = {}
    problems: list[str] = []
    for key, text in overrides.items():
        component, _, name = key.rpartition(".")
        description = descriptions.get(component)
        channel = description.channel(name) if description else None
        if channel is None or channel.causality is Causality.OUTPUT:
            problems.append(
                f"--param {key}: no parameter or input '{name}' on component '{component}'"
            )
            continue
        try:
            values.setdefault(component, {})[name] = _parse(channel.type, text)
        except ValueError:
            problems.append(f"--param {key}={text}: not a valid {channel.type}")
    return values, problems


def _parse(kind: ValueType, text: str) -> Value:
    if kind is ValueType.REAL:
        return float(text)
    if kind in (ValueType.INTEGER, ValueType.ENUMERATION):
        return int(text)
    if kind is ValueType.BOOLEAN:
        if text.lower() not in ("true", "false", "1", "0"):
            raise ValueError(text)
        return text.lower() in ("true", "1")
    if kind is ValueType.BINARY:
        return bytes.fromhex(text)
    return text


def _coerce(channel: Channel, value: Value) -> Value:
    if channel.type is ValueType.REAL and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def algorithm_of(scenario: ssp.Scenario) -> Algorithm:
    """The scenario's own choice: OpenMCx stepType ``sequential`` is Gauss-Seidel, the
    ``parallel_*`` types are Jacobi; Jacobi when the SSD says nothing."""
    if scenario.step_type == "sequential":
        return Algorithm.GAUSS_SEIDEL
    return Algorithm.JACOBI


def grid_of(scenario: ssp.Scenario, options: RunOptions) -> TimeGrid:
    start = options.start_time if options.start_time is not None else scenario.start_time or 0.0
    stop = options.stop_time if options.stop_time is not None else scenario.stop_time
    step = options.step_size if options.step_size is not None else scenario.step_size
    if stop is None:
        raise ScenarioError(
            f"{scenario.source.name}: no stop time; give --stop-time T or a DefaultExperiment "
            f"stopTime in the SSD"
        )
    if step is None:
        raise ScenarioError(
            f"{scenario.source.name}: no step size; give --step H or an OpenMCx task deltaTime "
            f"in the SSD"
        )
    return TimeGrid.between(start, stop, step)


def build_plan(
    scenario: ssp.Scenario,
    participants: Mapping[str, Participant],
    descriptions: Mapping[str, Description],
    options: RunOptions,
    *,
    problems: Sequence[str] = (),
) -> Plan:
    """The plan, or ValidationError listing every problem, ``problems`` found earlier first
    (participants that could not be described are left out of the checks that need them)."""
    problems = [*problems, *check_participants(scenario, descriptions)]
    overrides, override_problems = parse_overrides(options.parameters, descriptions)
    problems += override_problems
    grid: TimeGrid | None = None
    try:
        grid = grid_of(scenario, options)
    except ScenarioError as exc:
        problems.append(str(exc))
    links: list[Link] = []
    for connection in scenario.connections:
        try:
            links.append(_link(scenario, connection, descriptions))
        except ScenarioError as exc:
            problems.append(str(exc))
    members: list[Member] = []
    for component in scenario.components:
        description = descriptions.get(component.name)
        if description is None:
            continue
        try:
            members.append(
                _member(
                    component,
                    participants[component.name],
                    description,
                    overrides.get(component.name, {}),
                    grid,
                )
            )
        except ScenarioError as exc:
            problems.append(str(exc))
    algorithm = options.algorithm or algorithm_of(scenario)
    if algorithm is Algorithm.GAUSS_SEIDEL and len(members) == len(scenario.components):
        try:
            gauss_seidel_order(members, links)
        except ScenarioError as exc:
            problems.append(str(exc))
    if problems or grid is None:
        raise ValidationError(problems, subject=scenario.source.name)
    return Plan(
        members=tuple(members),
        links=tuple(links),
        grid=grid,
        algorithm=algorithm,
        run_id=options.run_id,
        lease=lease_of(options, grid, max((m.multiple for m in members), default=1)),
        realtime_factor=options.realtime_factor,
    )


def lease_of(options: RunOptions, grid: TimeGrid, multiple: int) -> float:
    """The lease: given, else the larger of 60 s and four call deadlines, and at least three
    paced steps of the slowest member (so pacing never looks like silence)."""
    if options.lease is not None:
        return options.lease
    lease = max(60.0, 4 * options.call_timeout)
    if options.realtime_factor:
        lease = max(lease, 3 * grid.step * multiple / options.realtime_factor)
    return lease


def _link(
    scenario: ssp.Scenario, connection: ssp.Connection, descriptions: Mapping[str, Description]
) -> Link:
    convert: Converter | None = ssp.converter(scenario, connection)
    if convert is ssp.identity:
        convert = None
    start = _channel(descriptions, connection.start_element, connection.start_connector)
    end = _channel(descriptions, connection.end_element, connection.end_connector)
    if start and end and (start.type, end.type) == (ValueType.INTEGER, ValueType.REAL):
        # the SSD may leave types to the participants: widen what they declare Integer
        inner = convert

        def widen(value: Value) -> Value:
            return inner(float(value)) if inner else float(value)

        convert = widen
    return Link(
        source=connection.start_element,
        output=connection.start_connector,
        target=connection.end_element,
        input=connection.end_connector,
        convert=convert,
        decoupled=connection.decoupled,
    )


def _member(
    component: ssp.Component,
    participant: Participant,
    description: Description,
    overrides: Mapping[str, Value],
    grid: TimeGrid | None,
) -> Member:
    parameters: dict[str, Value] = {}
    start_inputs: dict[str, Value] = {}
    bound = {name: p.value for name, p in component.parameters.items()} | dict(overrides)
    for name, value in bound.items():
        channel = description.channel(name)
        if channel is None or channel.causality is Causality.OUTPUT:
            raise ScenarioError(
                f"{_where(component)}: parameter binding '{component.name}.{name}' names no "
                f"parameter or input of participant '{description.name}'"
            )
        target = parameters if channel.causality is Causality.PARAMETER else start_inputs
        target[name] = _coerce(channel, value)
    multiple = 1
    if component.delta_time is not None and grid is not None:
        ratio = component.delta_time / grid.step
        multiple = round(ratio)
        if multiple < 1 or abs(ratio - multiple) > 1e-9 * max(1.0, ratio):
            raise ScenarioError(
                f"{_where(component)}: component '{component.name}' deltaTime "
                f"{component.delta_time:g} s is not a whole multiple of the step {grid.step:g} s"
            )
        if grid.steps % multiple:
            raise ScenarioError(
                f"{_where(component)}: component '{component.name}' deltaTime "
                f"{component.delta_time:g} s does not divide the run {grid.start:g} .. "
                f"{grid.stop:g} s ({grid.steps} steps of {grid.step:g} s); choose a stop time "
                f"the component reaches by whole steps of {component.delta_time:g} s"
            )
    fixed = description.capabilities.fixed_step_size
    if fixed and grid is not None:
        step = grid.step * multiple
        if not fits_fixed_step(step, fixed):
            raise ScenarioError(
                f"{_where(component)}: participant '{component.name}' steps in whole multiples "
                f"of {fixed:g} s, but its communication step is {step:g} s; choose --step "
                f"(or its deltaTime) as a multiple of {fixed:g} s"
            )
    return Member(
        name=component.name,
        participant=participant,
        outputs=description.of(Causality.OUTPUT),
        multiple=multiple,
        parameters=parameters,
        start_inputs=start_inputs,
    )


async def close_all(participants: Sequence[Participant]) -> None:
    """Close every participant, whatever happens to the others."""
    await asyncio.gather(*(p.close() for p in participants), return_exceptions=True)
