"""Stage 2: the participant behind each component — an FMU in-process or a remote participant —
opened and described, all at once; closed again on every path.

Local and remote participants look the same to every later stage (``coupler.participant``).
What could not be created, reached or described becomes a problem for ``checks`` to report
together with everything else.
"""

from __future__ import annotations

import asyncio
import functools
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager, suppress
from functools import partial
from pathlib import Path

from coupler.archives import Budget, declared_size
from coupler.channels import Description
from coupler.client import RemoteParticipant, StepTransport, parse_address, uses_tls
from coupler.errors import CouplerError, ScenarioError
from coupler.fmu import FmuParticipant
from coupler.fmu.host import IsolatedFmu
from coupler.participant import Participant
from coupler.security import ClientSecurity
from coupler_orchestrator import ssp
from coupler_orchestrator.model import Candidate, Roster
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.pipeline.builtins import builtin_of
from coupler_orchestrator.pipeline.replay import ReplayParticipant, parse_source


def where(item: ssp.Component | ssp.Connection | ssp.Connector, file: str = "") -> str:
    """``file line N`` of an SSD item, for messages."""
    return f"{_file_name(getattr(item, 'file', '') or file)} line {item.line}"


@functools.lru_cache(maxsize=64)
def _file_name(path: str) -> str:
    return Path(path).name or "scenario"


StepTransports = Callable[[], StepTransport | None]
"""What gives each remote participant of a run its step transport (None: ``grpc.aio``); the
runner chooses it (the master's native step channel, ``native_step_channel.transport``)."""


def create(
    component: ssp.Component,
    options: RunOptions,
    budget: Budget | None = None,
    *,
    steps: StepTransports | None = None,
) -> Participant:
    """The participant behind a component: an FMU in-process or isolated in a child process,
    or a remote one (its steps over ``steps()``'s transport, when it gives one); the component's
    own settings (SSD annotation) over the options."""
    replay = replay_of(component, options)
    if replay is not None:
        return replay
    builtin = builtin_of(component)
    if builtin is not None:
        return builtin
    settings = component.settings
    call_timeout = settings.call_timeout or options.call_timeout
    if component.type == ssp.FMU_TYPE:
        isolate = options.isolate_fmus if settings.isolate is None else settings.isolate
        if isolate:
            return IsolatedFmu(
                component.source, name=component.name, call_timeout=call_timeout, budget=budget
            )
        return FmuParticipant(Path(component.source), name=component.name, budget=budget)
    if component.type == ssp.GRPC_TYPE:
        own = ClientSecurity(
            ca=settings.tls_ca,
            cert=settings.tls_cert,
            key=settings.tls_key,
            token_file=settings.token_file,
        )
        transport = steps() if steps is not None else None
        address = address_of(component, options)
        return RemoteParticipant(
            address,
            steps=transport,
            streaming=transport is None,  # a transport given takes the stream where there is one
            name=component.name,
            connect_timeout=options.connect_timeout,
            call_timeout=call_timeout,
            max_message_bytes=options.max_message_bytes,
            security=options.security.override(own),
            on_waiting=(
                partial(options.on_waiting, component.name, address) if options.on_waiting else None
            ),
        )
    raise ScenarioError(
        f"{where(component)}: component '{component.name}' has type '{component.type}'; "
        f"supported: {ssp.FMU_TYPE}, {ssp.GRPC_TYPE}"
    )


def address_of(component: ssp.Component, options: RunOptions) -> str:
    """Where the remote participant of ``component`` is: its source, unless the run's
    ``addresses`` move it (by component name, or by the address its source names)."""
    if component.name in options.addresses:
        return options.addresses[component.name]
    if uses_tls(component.source):
        return component.source
    target = _target(component.source)
    for address, moved in options.addresses.items():
        if target is not None and _target(address) == target:
            return moved
    return component.source


def _target(address: str) -> str | None:
    with suppress(ScenarioError):
        return parse_address(address)
    return None


def replay_of(component: ssp.Component, options: RunOptions) -> ReplayParticipant | None:
    """The recording served in the component's place: ``--replay COMPONENT=PATH`` or a
    ``replay:PATH#Component`` source; None when the component is not replayed."""
    given = options.replays.get(component.name)
    if given is not None:
        return ReplayParticipant(given, component.name, name=component.name)
    if component.source.startswith(ssp.REPLAY_SCHEME):
        path, recorded = parse_source(component.source)
        return ReplayParticipant(path, recorded, name=recorded or component.name)
    return None


def units_of(participant: Participant) -> dict[str, ssp.BaseUnit]:
    """The unit definitions an FMU's modelDescription carries (FMI 2 and 3), by name."""
    if not isinstance(participant, FmuParticipant | IsolatedFmu):
        return {}
    units = {}
    for unit in participant.model_description.unitDefinitions:
        base = unit.baseUnit
        if unit.name and base is not None:
            units[unit.name] = ssp.BaseUnit(
                kg=base.kg,
                m=base.m,
                s=base.s,
                A=base.A,
                K=base.K,
                mol=base.mol,
                cd=base.cd,
                rad=base.rad,
                factor=float(base.factor),
                offset=float(base.offset),
            )
    return units


@asynccontextmanager
async def opened(
    scenario: ssp.Scenario,
    options: RunOptions,
    budget: Budget | None = None,
    *,
    steps: StepTransports | None = None,
) -> AsyncIterator[Roster]:
    """Create, open and describe every component's participant concurrently; close them all on
    the way out, whatever happened. FMUs, in-process and isolated, unpack within ``budget``
    (shared with the scenario's archive) before any of them starts; remote participants step
    over ``steps()``'s transports."""
    created: dict[str, Participant] = {}
    problems: list[str] = []
    known = [c.name for c in scenario.components]
    for unknown in sorted(set(options.replays) - set(known)):
        problems.append(
            f"--replay {unknown}: no component '{unknown}' in the scenario (components: "
            f"{', '.join(known)})"
        )
    for unknown in sorted(set(options.addresses) - set(known)):
        if "://" not in unknown:  # a component's name, not an address the fleet moved
            problems.append(
                f"--address {unknown}: no component '{unknown}' in the scenario (components: "
                f"{', '.join(known)})"
            )
    for component in scenario.components:
        try:
            created[component.name] = create(component, options, budget, steps=steps)
        except CouplerError as exc:
            problems.append(str(exc))
    try:
        if budget is not None:
            await _check_budget(created, budget, Path(scenario.source).name)
        names = list(created)
        results = await asyncio.gather(
            *(_describe(created[n]) for n in names), return_exceptions=True
        )
        candidates = {}
        for name, result in zip(names, results, strict=True):
            component = scenario.component(name)
            assert component is not None
            description = None
            if isinstance(result, CouplerError):
                problems.append(f"{where(component)}: component '{name}': {result}")
            elif isinstance(result, BaseException):
                if not isinstance(result, Exception):
                    raise result  # cancelled, interrupted: not a problem to report
                problems.append(
                    f"{where(component)}: component '{name}': {type(result).__name__}: {result}"
                )
            else:
                description = result
            candidates[name] = Candidate(
                component=component,
                participant=created[name],
                description=description,
                units=units_of(created[name]) if description is not None else {},
            )
        yield Roster(candidates=candidates, problems=tuple(problems))
    finally:
        await close_all(list(created.values()))


async def _check_budget(created: dict[str, Participant], budget: Budget, scenario: str) -> None:
    """Refuse, before any is unpacked, FMUs that would unpack to more than the budget left."""
    fmus = {n: p.path for n, p in created.items() if isinstance(p, FmuParticipant | IsolatedFmu)}
    if fmus:
        sizes = await asyncio.to_thread(
            lambda: {f"component '{n}'": declared_size(p) for n, p in fmus.items()}
        )
        budget.check(sizes, f"{scenario}: the FMUs")


async def _describe(participant: Participant) -> Description:
    await participant.open()
    return await participant.describe()


async def close_all(participants: list[Participant]) -> None:
    """Close every participant, whatever happens to the others."""
    await asyncio.gather(*(p.close() for p in participants), return_exceptions=True)
