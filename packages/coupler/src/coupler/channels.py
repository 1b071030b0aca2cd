"""What a participant declares: its channels, capabilities and the set-up of a run.

Plain, frozen Python values; ``coupler.values`` converts them to and from protobuf.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from functools import cached_property

#: A value on a channel, as Python sees it. Enumerations travel as ``int``.
Value = float | int | bool | str | bytes


class Causality(StrEnum):
    """Direction of a channel, named as in FMI/SSP."""

    INPUT = "input"
    OUTPUT = "output"
    PARAMETER = "parameter"


class ValueType(StrEnum):
    """Type of a channel, named as SSP connector types."""

    REAL = "Real"
    INTEGER = "Integer"
    BOOLEAN = "Boolean"
    STRING = "String"
    BINARY = "Binary"
    ENUMERATION = "Enumeration"


@dataclass(frozen=True, kw_only=True)
class Channel:
    """One channel of a participant."""

    name: str
    """Channel name; the SSD connector name that refers to it."""
    causality: Causality
    """Input, output or parameter."""
    type: ValueType
    """Value type."""
    unit: str = ""
    """Unit symbol as in the SSD's Units; empty when dimensionless."""
    start: Value | None = None
    """Start value, or None when the channel has none."""
    description: str = ""
    """Free text for people."""
    message_type: str = ""
    """For binary channels: full protobuf message name carried, e.g. ``coupler.v1.TrainState``."""
    max_bytes: int = 0
    """For Binary and String channels: the largest value in bytes (a String's UTF-8 bytes) the
    participant sends on this output, or accepts on this input or parameter; 0: not declared
    (the message limit applies). Values over it are refused naming the channel; the
    participant's and the orchestrator's gRPC limits are derived from these maxima
    (docs/protocol.md "Message size")."""

    @property
    def sized(self) -> bool:
        """Whether the channel's values count towards a message's size (Binary and String)."""
        return self.type in (ValueType.BINARY, ValueType.STRING)


@dataclass(frozen=True, kw_only=True)
class Capabilities:
    """What a participant supports beyond the unary calls."""

    streaming: bool = True
    """Accepts the StepStream RPC."""
    variable_step_size: bool = True
    """Accepts any step size."""
    fixed_step_size: float = 0.0
    """When non-zero, every step size is a whole multiple of this [s] (``fits_fixed_step``)."""
    step_socket: str = ""
    """The unix socket path where the participant also serves its step loop without gRPC
    (docs/protocol.md "Step socket"); set by the runtime when it serves one, empty: none."""


@dataclass(frozen=True, kw_only=True)
class Description:
    """A participant's answer to Describe."""

    name: str
    """The participant's own name (the SSD may call it differently)."""
    channels: tuple[Channel, ...]
    """Every channel, in the participant's order."""
    capabilities: Capabilities = field(default_factory=Capabilities)
    """Optional features."""
    implementation: str = ""
    """Implementation and version, for run summaries."""

    def channel(self, name: str) -> Channel | None:
        """The channel called ``name``, or None."""
        return self._by_name.get(name)

    @cached_property
    def _by_name(self) -> dict[str, Channel]:
        """Channels by name (the first of a name), looked up once per name, not per search."""
        by_name: dict[str, Channel] = {}
        for c in self.channels:
            by_name.setdefault(c.name, c)
        return by_name

    def of(self, causality: Causality) -> tuple[Channel, ...]:
        """Channels of one causality, in order."""
        return tuple(c for c in self.channels if c.causality is causality)


@dataclass(frozen=True, kw_only=True)
class RunSetup:
    """Everything Initialize carries."""

    run_id: str
    """Identifies the run in logs and results."""
    start_time: float
    """Simulation start time [s]: the time of the outputs ``initialize`` returns."""
    step_size: float
    """Communication step size of this participant [s]: the ``step`` of its ``do_step`` calls
    (its own deltaTime where the SSD gives it one, else the run's step)."""
    stop_time: float | None = None
    """Simulation stop time [s], when known."""
    parameters: Mapping[str, Value] = field(default_factory=dict)
    """Parameter values by channel name: those the SSD binds and ``--param`` sets, no others (the
    participant uses its channels' start values for the rest)."""
    inputs: Mapping[str, Value] = field(default_factory=dict)
    """Start values of inputs by channel name: those the SSD binds, no others (the participant
    uses its channels' start values for the rest until a connection drives them)."""
    lease: float = 0.0
    """The run's lease [s]: silence this long ends the run at the participant; 0 = its
    default. Applied by the participant runtime (``coupler.server``), not by participants."""
    run_secret: bytes = field(default=b"", repr=False, compare=False)
    """The run's secret, which every call of the run carries (``coupler.client`` makes one when
    empty). Checked by the participant runtime, never shown to participants, never logged."""


#: Relative tolerance of "a whole multiple of fixed_step_size" (protocol: component.proto).
STEP_TOLERANCE = 1e-9


def fits_fixed_step(step: float, fixed: float) -> bool:
    """Whether ``step`` is n * ``fixed`` for a whole n >= 1, within ``STEP_TOLERANCE``."""
    if not fixed:
        return True
    ratio = step / fixed
    n = round(ratio)
    return n >= 1 and abs(ratio - n) <= STEP_TOLERANCE * max(1.0, ratio)
