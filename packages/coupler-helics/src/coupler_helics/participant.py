"""A Coupler participant that is a HELICS value federate: ``HelicsParticipant``.

    coupler-helics helics.toml --port 50071      # serves it over gRPC

What maps to what (docs/frameworks.md):

- Channels: each ``[[publication]]`` is an input (Coupler -> HELICS), each ``[[subscription]]``
  an output (HELICS -> Coupler), with its type and unit (HELICS converts a publication's unit to
  the subscription's); ``broker`` and ``federate`` are String parameters.
- Initialize: the federate joins the federation at the broker, publishes the inputs' start
  values while the federation initializes and enters executing mode (HELICS time 0 is
  Coupler's ``start_time``); the outputs are the subscriptions' values then.
- DoStep from t to t + h: the inputs are published at t, HELICS time t + h - start_time is
  requested and granted (lockstep: one request and one grant per communication point), the
  outputs are the subscriptions' values at t + h. A value another federate publishes at t
  reaches Coupler's results at t; one Coupler publishes at t reaches the other federates when
  they are next granted a time after t (t + h on the same grid).
- Terminate: the federate disconnects; a new run joins again.
- Errors: a broker that cannot be reached or that ends during the run fails the call with
  UNAVAILABLE naming the broker, within the file's ``timeout`` (5 s; HELICS's own 30 s would
  outlast the orchestrator's call deadline); the run fails, what was recorded stays.
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from pathlib import Path

from coupler.channels import (
    Capabilities,
    Causality,
    Channel,
    Description,
    RunSetup,
    Value,
    ValueType,
)
from coupler.errors import ParticipantError
from coupler.participant import Participant, Values
from coupler.values import coerce
from coupler_helics.config import HelicsConfig, Interface
from coupler_helics.federate import Federate


class HelicsParticipant(Participant):
    """The federate, one run at a time."""

    def __init__(self, config: HelicsConfig) -> None:
        self.config = config
        self._channels = (
            Channel(
                name="broker",
                causality=Causality.PARAMETER,
                type=ValueType.STRING,
                start=config.broker,
                description="the helics_broker's HOST:PORT",
            ),
            Channel(
                name="federate",
                causality=Causality.PARAMETER,
                type=ValueType.STRING,
                start=config.federate,
                description="the federate's name in the federation",
            ),
            *(_channel(i, Causality.INPUT) for i in config.publication),
            *(_channel(i, Causality.OUTPUT) for i in config.subscription),
        )
        self._federate: Federate | None = None
        self._start = Fraction(0)
        self._held: dict[str, Value] = {}

    @classmethod
    def from_file(cls, path: str | Path) -> HelicsParticipant:
        return cls(HelicsConfig.load(path))

    async def describe(self) -> Description:
        return Description(
            name=self.config.name,
            channels=self._channels,
            capabilities=Capabilities(),
            implementation=f"coupler-helics (HELICS {_version()})",
        )

    async def initialize(self, setup: RunSetup) -> Values:
        await self._leave()
        broker = str(setup.parameters.get("broker", self.config.broker))
        name = str(setup.parameters.get("federate", self.config.federate))
        self._start = Fraction(repr(setup.start_time))
        starts = {
            i.channel: setup.inputs.get(i.channel, coerce(i.type, i.start))
            for i in self.config.publication
            if i.channel in setup.inputs or i.start is not None
        }
        self._federate = Federate(self.config.name, self.config, broker, name)
        return await self._federate.join(starts)

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        if self._federate is None:
            raise ParticipantError(
                "no run: Initialize first",
                participant=self.config.name,
                call="DoStep",
                status="FAILED_PRECONDITION",
            )
        to = float(Fraction(repr(time)) + Fraction(repr(step)) - self._start)
        return await self._federate.advance(to, inputs)

    async def terminate(self, reason: str = "") -> None:
        await self._leave()

    async def close(self) -> None:
        await self._leave()

    async def _leave(self) -> None:
        federate, self._federate = self._federate, None
        if federate is not None:
            await federate.leave()


def _channel(i: Interface, causality: Causality) -> Channel:
    return Channel(
        name=i.channel,
        causality=causality,
        type=i.type,
        unit=i.unit,
        start=coerce(i.type, i.start) if i.start is not None else None,
        description=i.description
        or f"HELICS {'publication' if causality is Causality.INPUT else 'subscription to'} {i.key}",
    )


def _version() -> str:
    import helics

    return str(helics.helicsGetVersion()).split()[0]
