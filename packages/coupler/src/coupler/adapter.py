"""The adapter pattern of the published design: wrap an existing simulator in one small class.

An ``Adapter`` speaks the simulator's own language (its field names, its API); an
``AdapterParticipant`` turns it into a ``Participant`` using a channel mapping read from a TOML
file, so renaming a channel or exposing another field is a configuration edit::

    name = "OpenRails"

    [[channel]]
    name = "speed"            # channel name the SSD connects
    causality = "output"
    type = "Real"
    unit = "m/s"
    field = "locomotiveState.v"   # dotted path into get_state()
    scale = 1.0                   # channel = scale * field + offset (Real only)

    [[channel]]
    name = "throttle"
    causality = "input"
    type = "Real"
    field = "THROTTLE"        # key apply_inputs() receives
    start = 0.0

    [[channel]]
    name = "frame"
    causality = "output"
    type = "Binary"
    field = "camera.frame"
    max_bytes = 1440256       # the largest value sent (Binary and String; docs/protocol.md)
"""

from __future__ import annotations

import tomllib
from abc import ABC, abstractmethod
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field
from pydantic import ValidationError as PydanticValidationError

from coupler.channels import (
    Capabilities,
    Causality,
    Channel,
    Description,
    RunSetup,
    Value,
    ValueType,
)
from coupler.errors import ParticipantError, ScenarioError
from coupler.participant import HealthReport, Participant, Values
from coupler.values import coerce


class Adapter(ABC):
    """A simulator, seen through its own field names."""

    @abstractmethod
    async def connect(self) -> None:
        """Reach the simulator and wait until it is ready (with a timeout)."""

    async def start(self, setup: RunSetup, parameters: Mapping[str, Value]) -> None:  # noqa: B027
        """A run begins; ``parameters`` are keyed by field. Nothing to do by default."""

    @abstractmethod
    async def get_state(self) -> Mapping[str, Any]:
        """The simulator's current state; mapped channels read dotted paths from it."""

    @abstractmethod
    async def apply_inputs(self, inputs: Mapping[str, Value]) -> None:
        """Apply inputs keyed by field."""

    @abstractmethod
    async def advance(self, time: float, step: float) -> None:
        """Advance the simulator from ``time`` by ``step`` seconds."""

    async def stop(self, reason: str) -> None:  # noqa: B027
        """The run ended. Nothing to do by default."""

    @abstractmethod
    async def shutdown(self) -> None:
        """Release the connection to the simulator."""

    async def watch_health(self, report: HealthReport) -> None:
        """Whether the simulator can take a run; see ``Participant.watch_health``."""
        await report(None)


class ChannelMap(BaseModel):
    """One channel and the simulator field behind it."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    """Channel name, as the SSD connector names it."""
    causality: Causality
    """input, output or parameter."""
    type: ValueType
    """Real, Integer, Boolean, String, Binary or Enumeration."""
    field: str
    """Dotted path into ``get_state()`` (outputs) or the key ``apply_inputs()`` receives."""
    unit: str = ""
    """Unit symbol."""
    start: float | int | bool | str | None = None
    """Start value (inputs and parameters); a Binary channel's is text, its UTF-8 bytes."""
    scale: float = 1.0
    """Real channels: channel = scale * field + offset."""
    offset: float = 0.0
    """Real channels: see scale."""
    description: str = ""
    """Free text."""
    message_type: str = ""
    """Binary channels: full protobuf message name."""
    max_bytes: int = Field(default=0, ge=0)
    """Binary and String channels: the largest value sent on this output or accepted on this
    input or parameter [bytes]; 0: not declared (``Channel.max_bytes``)."""


class AdapterConfig(BaseModel):
    """A participant made from an adapter: its name and channel mapping."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    """Participant name reported by Describe."""
    channel: list[ChannelMap] = Field(min_length=1)
    """Every channel, in order."""
    fixed_step_size: float = 0.0
    """Non-zero: step sizes must be multiples of this [s]."""

    @classmethod
    def load(cls, path: str | Path) -> AdapterConfig:
        """Read a TOML channel mapping; ScenarioError naming the file and the bad entry."""
        path = Path(path)
        try:
            return cls.model_validate(tomllib.loads(path.read_text(encoding="utf-8")))
        except OSError as exc:
            raise ScenarioError(f"cannot read channel mapping {path}: {exc.strerror}") from exc
        except tomllib.TOMLDecodeError as exc:
            raise ScenarioError(f"{path}: not valid TOML: {exc}") from exc
        except PydanticValidationError as exc:
            problems = "; ".join(
                f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()
            )
            raise ScenarioError(f"{path}: invalid channel mapping: {problems}") from exc


def lookup(state: Mapping[str, Any], path: str) -> Any:
    """``state['a']['b']`` for ``'a.b'``; KeyError naming the missing part."""
    node: Any = state
    for part in path.split("."):
        if isinstance(node, Mapping) and part in node:
            node = node[part]
        else:
            raise KeyError(f"field '{path}' has no '{part}'")
    return node


class AdapterParticipant(Participant):
    """A ``Participant`` made of an ``Adapter`` and its channel mapping."""

    def __init__(
        self, adapter: Adapter, config: AdapterConfig, *, implementation: str = ""
    ) -> None:
        self.adapter = adapter
        self.config = config
        self.implementation = implementation or type(adapter).__name__
        self._outputs = [c for c in config.channel if c.causality is Causality.OUTPUT]
        self._by_name = {c.name: c for c in config.channel}

    async def open(self) -> None:
        await self.adapter.connect()

    async def close(self) -> None:
        await self.adapter.shutdown()

    async def watch_health(self, report: HealthReport) -> None:
        await self.adapter.watch_health(report)

    async def describe(self) -> Description:
        fixed = self.config.fixed_step_size
        return Description(
            name=self.config.name,
            implementation=self.implementation,
            capabilities=Capabilities(variable_step_size=not fixed, fixed_step_size=fixed),
            channels=tuple(
                Channel(
                    name=c.name,
                    causality=c.causality,
                    type=c.type,
                    unit=c.unit,
                    start=_start(c),
                    description=c.description,
                    message_type=c.message_type,
                    max_bytes=c.max_bytes,
                )
                for c in self.config.channel
            ),
        )

    async def initialize(self, setup: RunSetup) -> Values:
        defaults = {
            c.name: start
            for c in self.config.channel
            if (start := _start(c)) is not None and c.causality is not Causality.OUTPUT
        }
        parameters = {
            **{
                n: v
                for n, v in defaults.items()
                if self._by_name[n].causality is Causality.PARAMETER
            },
            **setup.parameters,
        }
        inputs = {
            **{n: v for n, v in defaults.items() if self._by_name[n].causality is Causality.INPUT},
            **setup.inputs,
        }
        await self.adapter.start(setup, self._to_fields(parameters))
        if inputs:
            await self.adapter.apply_inputs(self._to_fields(inputs))
        return await self._read_outputs()

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        if inputs:
            await self.adapter.apply_inputs(self._to_fields(inputs))
        await self.adapter.advance(time, step)
        return await self._read_outputs()

    async def terminate(self, reason: str = "") -> None:
        await self.adapter.stop(reason)

    def _to_fields(self, values: Mapping[str, Value]) -> dict[str, Value]:
        fields: dict[str, Value] = {}
        for name, value in values.items():
            c = self._by_name[name]
            if c.type is ValueType.REAL and (c.scale != 1.0 or c.offset != 0.0):
                value = (float(value) - c.offset) / c.scale
            fields[c.field] = value
        return fields

    async def _read_outputs(self) -> Values:
        state = await self.adapter.get_state()
        outputs: Values = {}
        for c in self._outputs:
            try:
                raw = lookup(state, c.field)
            except KeyError as exc:
                raise ParticipantError(
                    f"{exc.args[0]} in the simulator's state, needed by channel '{c.name}' "
                    f"(fix the field in the channel mapping of '{self.config.name}')",
                    participant=self.config.name,
                    call="get_state",
                ) from exc
            outputs[c.name] = _typed(c, raw)
        return outputs


def _start(c: ChannelMap) -> Value | None:
    """A channel's start value as its type; a Binary one is written as text (its UTF-8 bytes:
    ``start = ""`` is an empty message)."""
    if c.start is None:
        return None
    if c.type is ValueType.BINARY and isinstance(c.start, str):
        return c.start.encode("utf-8")
    return coerce(c.type, c.start)


def _typed(c: ChannelMap, raw: Any) -> Value:
    """A state field as the channel's value (scale and offset for Real)."""
    value = coerce(c.type, raw)
    return float(value) * c.scale + c.offset if c.type is ValueType.REAL else value
