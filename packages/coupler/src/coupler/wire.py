"""Python values <-> protobuf messages of the protocol. The only module that builds or reads them.

Every value is checked against its channel's description (``coupler.values.check``): the
type, the int32 range, the NaN/Inf policy, the maximum a Binary or String channel declares and
the message limit of Binary and String values together. Errors name the channel and what it
expects. ``coupler.server`` and ``coupler.client`` call these functions; the rest of Coupler
speaks Python values.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NoReturn, TypeAlias, TypeVar

from coupler.channels import (
    Capabilities,
    Causality,
    Channel,
    Description,
    RunSetup,
    Value,
    ValueType,
)
from coupler.errors import ChannelValueError, MessageTooLarge, ValueTooLarge, foreign
from coupler.v1 import component_pb2 as pb

if TYPE_CHECKING:
    from google.protobuf.internal.containers import RepeatedCompositeFieldContainer
    from google.protobuf.message import Message

    from coupler.costs import StepMeter

    RepeatedBindings = RepeatedCompositeFieldContainer[pb.VariableBinding]
from coupler.values import (
    DEFAULT_POLICY,
    INT32_MAX,
    INT32_MIN,
    MAX_MESSAGE_BYTES,
    ValuePolicy,
    check,
    message_limit,
)

_FIELD_OF_TYPE = {
    ValueType.REAL: "real",
    ValueType.INTEGER: "integer",
    ValueType.ENUMERATION: "integer",
    ValueType.BOOLEAN: "boolean",
    ValueType.STRING: "text",
    ValueType.BINARY: "binary",
}
_FIELD_NUMBER = {f.name: f.number for f in pb.VariableBinding.DESCRIPTOR.fields}
"""Each field of ``VariableBinding`` by name: its number on the wire."""
_KIND_OF_FIELD = {
    "real": "Real",
    "integer": "Integer",
    "boolean": "Boolean",
    "text": "String",
    "binary": "Binary",
}
_CAUSALITY_TO_PB = {
    Causality.INPUT: pb.CAUSALITY_INPUT,
    Causality.OUTPUT: pb.CAUSALITY_OUTPUT,
    Causality.PARAMETER: pb.CAUSALITY_PARAMETER,
}
_CAUSALITY_FROM_PB = {v: k for k, v in _CAUSALITY_TO_PB.items()}
_TYPE_TO_PB = {
    ValueType.REAL: pb.VALUE_TYPE_REAL,
    ValueType.INTEGER: pb.VALUE_TYPE_INTEGER,
    ValueType.BOOLEAN: pb.VALUE_TYPE_BOOLEAN,
    ValueType.STRING: pb.VALUE_TYPE_STRING,
    ValueType.BINARY: pb.VALUE_TYPE_BINARY,
    ValueType.ENUMERATION: pb.VALUE_TYPE_ENUMERATION,
}
_TYPE_FROM_PB = {v: k for k, v in _TYPE_TO_PB.items()}
_PYTHON_TYPE: dict[ValueType, type] = {
    ValueType.REAL: float,
    ValueType.INTEGER: int,
    ValueType.ENUMERATION: int,
    ValueType.BOOLEAN: bool,
    ValueType.STRING: str,
    ValueType.BINARY: bytes,
}
_PLAIN, _FINITE, _INT32 = 0, 1, 2
"""What a value of the right Python type still needs checked: nothing, that it is finite (a
Real), that it fits int32 (an Integer or Enumeration)."""
_LIMIT_OF_TYPE = {ValueType.REAL: _FINITE, ValueType.INTEGER: _INT32, ValueType.ENUMERATION: _INT32}
_UTF8_MAX = 4
"""Bytes of one character in UTF-8 at most: a text's length times this bounds its size."""

# Message classes, re-exported so that server and client name them through this module.
DescribeRequest = pb.DescribeRequest
DescribeResponse = pb.DescribeResponse
InitializeRequest = pb.InitializeRequest
InitializeResponse = pb.InitializeResponse
DoStepRequest = pb.DoStepRequest
DoStepResponse = pb.DoStepResponse
TerminateRequest = pb.TerminateRequest
TerminateResponse = pb.TerminateResponse
SERVICE_NAME = pb.DESCRIPTOR.services_by_name["GRPCComponentService"].full_name

FRAMING_BYTES = 8 * 1024 * 1024
"""What a message may carry beyond its Binary and String values (names, numbers, ids) [bytes]."""
_GRPC_MAX = 2**31 - 1
"""The largest message gRPC's limits can express (a C int) [bytes]."""


@dataclass(frozen=True, slots=True)
class MessageLimits:
    """The Binary and String values one message may carry together [bytes], received and sent
    by one end of a gRPC connection; its transport lets ``FRAMING_BYTES`` more through, so the
    codec names the channel of a message over the limit and the transport refuses only what is
    larger still (its RESOURCE_EXHAUSTED names no channel)."""

    received: int = MAX_MESSAGE_BYTES
    sent: int = MAX_MESSAGE_BYTES

    @property
    def transport(self) -> tuple[int, int]:
        """gRPC's receive and send limits [bytes]: the values' plus framing."""
        return (
            min(self.received + FRAMING_BYTES, _GRPC_MAX),
            min(self.sent + FRAMING_BYTES, _GRPC_MAX),
        )

    def options(self) -> tuple[tuple[str, int], ...]:
        """gRPC channel/server options for these limits."""
        receive, send = self.transport
        return (
            ("grpc.max_receive_message_length", receive),
            ("grpc.max_send_message_length", send),
        )


def served_limits(description: Description, max_message_bytes: int) -> MessageLimits:
    """A participant's server's limits: it receives its parameters and inputs (the sum of
    their declared maxima; ``max_message_bytes`` when one is undeclared) and sends its outputs
    (likewise)."""
    policy = ValuePolicy(max_message_bytes=max_message_bytes)
    return MessageLimits(
        received=message_limit(
            (c for c in description.channels if c.causality is not Causality.OUTPUT), policy
        ),
        sent=message_limit(description.of(Causality.OUTPUT), policy),
    )


def client_limits(description: Description, max_message_bytes: int) -> MessageLimits:
    """The limits of a client of the participant ``description``: it receives the outputs (the
    sum of their declared maxima, at most ``max_message_bytes``) and sends parameters and
    inputs (likewise). Where one is undeclared: at least what a participant's server sends by
    default, so that an answer over ``max_message_bytes`` arrives and is refused naming its
    channel."""
    policy = ValuePolicy(max_message_bytes=max_message_bytes, cap_declared=True)
    floor = max(max_message_bytes, MAX_MESSAGE_BYTES)

    def limit(channels: Iterable[Channel]) -> int:
        sized = [c for c in channels if c.sized]
        if not sized or any(c.max_bytes <= 0 for c in sized):
            return floor
        return message_limit(sized, policy)

    return MessageLimits(
        received=limit(description.of(Causality.OUTPUT)),
        sent=limit(c for c in description.channels if c.causality is not Causality.OUTPUT),
    )


@dataclass(frozen=True, slots=True)
class _Slot:
    """One channel as the codec reads and writes it, worked out once per participant."""

    channel: Channel
    field: str
    """Its field of ``VariableBinding.value``."""
    python: type
    """The Python type of its values as they need no conversion (and as protobuf gives them)."""
    limit: int
    """``_PLAIN``, ``_FINITE`` or ``_INT32``: what such a value still needs checked."""
    weight: int
    """A value's length times this bounds its bytes in a message (0: not counted)."""
    maximum: int
    """The largest value the channel declares [bytes]; 0: none declared (or not counted)."""

    @classmethod
    def of(cls, channel: Channel) -> _Slot:
        weight = {ValueType.STRING: _UTF8_MAX, ValueType.BINARY: 1}.get(channel.type, 0)
        return cls(
            channel=channel,
            field=_FIELD_OF_TYPE[channel.type],
            python=_PYTHON_TYPE[channel.type],
            limit=_LIMIT_OF_TYPE.get(channel.type, _PLAIN),
            weight=weight,
            maximum=max(channel.max_bytes, 0) if weight else 0,
        )


_Allowed = tuple[Causality, ...] | None
_INPUTS, _OUTPUTS, _PARAMETERS = (Causality.INPUT,), (Causality.OUTPUT,), (Causality.PARAMETER,)


class Codec:
    """Encodes and decodes the bindings of one participant, checked against its channels.

    Per step it does no more than a step needs: each channel's field, Python type and limits
    are worked out once (``_Slot``); a value of the right type within its limits is taken as
    it is, anything else goes through ``coupler.values.check`` (which converts or names the
    channel); a decoded value's type is the protobuf field's own, so only a Real's finiteness
    is checked; and a value's or a message's size only when its length could exceed its
    channel's declared maximum or the message limit (``coupler.values.message_limit``: the
    declared maxima of the channels a message may carry, or the policy's limit).
    """

    def __init__(self, description: Description, policy: ValuePolicy = DEFAULT_POLICY) -> None:
        self.description = description
        self.policy = policy
        self._channels = {c.name: c for c in description.channels}
        self._tables: dict[_Allowed, dict[str, _Slot]] = {}
        self._limits: dict[_Allowed, int] = {}
        self._finite = not policy.allow_nonfinite

    def channel(self, name: str, allowed: Iterable[Causality] | None = None) -> Channel:
        """The channel ``name``, or ChannelValueError listing the channels there are."""
        channel = self._channels.get(name)
        wanted = set(allowed) if allowed is not None else None
        if channel is None or (wanted is not None and channel.causality not in wanted):
            candidates = sorted(
                c.name for c in self.description.channels if wanted is None or c.causality in wanted
            )
            kinds = "/".join(sorted(str(c) for c in wanted)) if wanted else "any"
            what = "no channel" if channel is None else f"no {kinds} channel"
            raise ChannelValueError(
                f"participant '{self.description.name}' has {what} '{name}' "
                f"({kinds} channels: {', '.join(candidates) or 'none'})",
                channel=name,
                expected=kinds,
            )
        return channel

    def _table(self, allowed: _Allowed) -> dict[str, _Slot]:
        """The slots of the channels of the causalities ``allowed`` (every one: None)."""
        table = self._tables.get(allowed)
        if table is None:
            table = {
                c.name: _Slot.of(c)
                for c in self.description.channels
                if allowed is None or c.causality in allowed
            }
            self._tables[allowed] = table
            self._limits[allowed] = message_limit((s.channel for s in table.values()), self.policy)
        return table

    def limit(self, allowed: Iterable[Causality] | None = None) -> int:
        """The message limit of values of the causalities ``allowed`` [bytes]."""
        key = tuple(allowed) if allowed is not None else None
        self._table(key)
        return self._limits[key]

    def encode(
        self, values: Mapping[str, object], allowed: Iterable[Causality] | None = None
    ) -> list[pb.VariableBinding]:
        """Bindings for ``values``, each checked against its channel (``encode_into`` a
        message of one's own)."""
        message = pb.DoStepRequest()
        self.encode_into(message.inputs, values, tuple(allowed) if allowed is not None else None)
        return list(message.inputs)

    def encode_into(
        self,
        bindings: RepeatedBindings,
        values: Mapping[str, object],
        allowed: tuple[Causality, ...] | None = None,
    ) -> None:
        """Adds the bindings of ``values`` to the repeated field ``bindings`` of a message,
        each checked against its channel (``encode``, without building each binding apart
        and copying it into the message)."""
        table = self._table(allowed)
        add = bindings.add
        size = 0
        for name, value in values.items():
            slot = table.get(name)
            if slot is None:
                self.channel(name, allowed)  # raises, naming the channels there are
                raise AssertionError("unreachable")
            binding = add()
            binding.channel = name
            setattr(binding, slot.field, self._checked(slot, value))
            if slot.weight:
                length = len(value) * slot.weight  # type: ignore[arg-type]
                if slot.maximum and length > slot.maximum:
                    _within(slot, value)  # type: ignore[arg-type]
                size += length
        if size > self._limits[allowed]:
            self._fits(values, allowed)

    def _checked(self, slot: _Slot, value: object) -> object:
        """``value`` as its channel carries it (``check``), at once when it is already."""
        if type(value) is slot.python:
            if slot.limit == _PLAIN:
                return value
            if slot.limit == _FINITE:
                if not self._finite or math.isfinite(value):  # type: ignore[arg-type]
                    return value
            elif INT32_MIN <= value <= INT32_MAX:
                return value
        return check(slot.channel, value, self.policy)

    def encode_apart(
        self,
        bindings: RepeatedBindings,
        values: Mapping[str, object],
        allowed: tuple[Causality, ...] | None = None,
    ) -> list[tuple[str, bytes]]:
        """``encode_into`` for every value but the long Binary ones (``LARGE_BYTES`` or more),
        which are returned by channel, checked, for the caller to write apart (``step_pieces``)."""
        table = self._table(allowed)
        large = [
            (name, value)
            for name, value in values.items()
            if type(value) is bytes
            and len(value) >= LARGE_BYTES
            and (slot := table.get(name)) is not None
            and slot.field == "binary"
        ]
        if not large:
            self.encode_into(bindings, values, allowed)
            return large
        apart = {name for name, _ in large}
        self.encode_into(bindings, {n: v for n, v in values.items() if n not in apart}, allowed)
        for name, value in large:
            slot = table[name]
            if slot.maximum and len(value) > slot.maximum:
                _within(slot, value)
        self._fits(values, allowed)
        return large

    def decode(
        self,
        bindings: Iterable[pb.VariableBinding],
        allowed: Iterable[Causality] | None = None,
        large: Iterable[tuple[str, bytes]] = (),
    ) -> dict[str, Value]:
        """Python values of ``bindings``, and of the Binary values ``large`` (by channel: those
        ``step_answer`` cut out of a message), each checked against its channel."""
        allowed = tuple(allowed) if allowed is not None else None
        table = self._table(allowed)
        values: dict[str, Value] = {}
        size = 0
        for binding in bindings:
            name = binding.channel
            slot = table.get(name)
            field = binding.WhichOneof("value")
            if slot is None or field != slot.field:
                self._refuse(binding, allowed)
            value = getattr(binding, field)
            if slot.limit == _FINITE and self._finite and not math.isfinite(value):
                check(slot.channel, value, self.policy)  # raises, naming the channel
            elif slot.weight:
                length = len(value) * slot.weight
                if slot.maximum and length > slot.maximum:
                    _within(slot, value)
                size += length
            values[name] = value
        for name, data in large:
            slot = table.get(name)
            if slot is None or slot.field != "binary":
                self._refuse(pb.VariableBinding(channel=name, binary=b""), allowed)
            if slot.maximum and len(data) > slot.maximum:
                _within(slot, data)
            size += len(data)
            values[name] = data
        if size > self._limits[allowed]:
            self._fits(values, allowed)
        return values

    def answer_fields(self) -> dict[str, tuple[int, int, bool]]:
        """Each output channel -> its ``VariableBinding`` field number, the weight of a value's
        length in a message's size, and whether a value must be finite: what a reader of step
        answers other than protobuf's needs to read them as ``decode`` does (the native step
        channel's, ``coupler_native._answers``); ``policy.max_message_bytes`` bounds the sum."""
        return {
            name: (_FIELD_NUMBER[slot.field], slot.weight, slot.limit == _FINITE and self._finite)
            for name, slot in self._table(_OUTPUTS).items()
        }

    def _refuse(self, binding: pb.VariableBinding, allowed: _Allowed) -> NoReturn:
        """ChannelValueError for a binding of no such channel or of the wrong type."""
        channel = self.channel(binding.channel, allowed)
        field = binding.WhichOneof("value")
        raise ChannelValueError(
            f"channel '{channel.name}' expects {channel.type}, got "
            f"{_KIND_OF_FIELD.get(field or '', 'no value')}",
            channel=channel.name,
            expected=str(channel.type),
        )

    def _fits(self, values: Mapping[str, object], allowed: _Allowed) -> None:
        """MessageTooLarge naming the largest channel when the Binary and String ``values`` of
        one message (of the causalities ``allowed``) together are over its message limit."""
        sizes = {n: _size(v) for n, v in values.items() if isinstance(v, bytes | bytearray | str)}
        total = sum(sizes.values())
        limit = self.limit(allowed)
        if total <= limit:
            return
        name = max(sizes, key=sizes.__getitem__)
        raise MessageTooLarge(
            channel=name,
            kind=str(self._channels[name].causality),
            size=sizes[name],
            total=total,
            limit=limit,
        )


def _size(value: bytes | bytearray | str) -> int:
    """Bytes of a value on the wire (UTF-8 for text)."""
    if isinstance(value, str) and not value.isascii():
        return len(value.encode())
    return len(value)


def _within(slot: _Slot, value: bytes | bytearray | str) -> None:
    """ValueTooLarge when ``value`` is over the maximum its channel declares (its length
    times the slot's weight only bounds a String's bytes)."""
    size = _size(value)
    if size > slot.maximum:
        channel = slot.channel
        raise ValueTooLarge(
            channel=channel.name, kind=str(channel.causality), size=size, maximum=slot.maximum
        )


def _untyped_binding(name: str, value: Value) -> pb.VariableBinding:
    binding = pb.VariableBinding(channel=name)
    if isinstance(value, bool):
        binding.boolean = value
    elif isinstance(value, int):
        binding.integer = value
    elif isinstance(value, float):
        binding.real = value
    elif isinstance(value, str):
        binding.text = value
    else:
        binding.binary = bytes(value)
    return binding


def _untyped_value(binding: pb.VariableBinding) -> Value:
    field = binding.WhichOneof("value")
    value: Value = getattr(binding, field) if field else 0.0
    return value


# --- Describe --------------------------------------------------------------------------------


def description_to_pb(description: Description) -> pb.DescribeResponse:
    """The Describe answer for ``description``."""
    caps = description.capabilities
    return pb.DescribeResponse(
        name=description.name,
        implementation=description.implementation,
        capabilities=pb.Capabilities(
            streaming=caps.streaming,
            variable_step_size=caps.variable_step_size,
            fixed_step_size=caps.fixed_step_size,
            step_socket=caps.step_socket,
        ),
        channels=[
            pb.ChannelDescription(
                name=c.name,
                causality=_CAUSALITY_TO_PB[c.causality],
                type=_TYPE_TO_PB[c.type],
                unit=c.unit,
                description=c.description,
                message_type=c.message_type,
                max_bytes=c.max_bytes,
                start=_untyped_binding(c.name, c.start) if c.start is not None else None,
            )
            for c in description.channels
        ],
    )


def description_from_pb(response: pb.DescribeResponse) -> Description:
    """The Python description carried by a Describe answer."""
    channels = []
    for c in response.channels:
        if c.causality not in _CAUSALITY_FROM_PB or c.type not in _TYPE_FROM_PB:
            raise ChannelValueError(
                f"participant '{response.name}' describes channel '{c.name}' with an "
                f"unspecified causality or type",
                channel=c.name,
            )
        channels.append(
            Channel(
                name=foreign(c.name),
                causality=_CAUSALITY_FROM_PB[c.causality],
                type=_TYPE_FROM_PB[c.type],
                unit=foreign(c.unit),
                description=foreign(c.description),
                message_type=foreign(c.message_type),
                max_bytes=c.max_bytes,
                start=_untyped_value(c.start) if c.HasField("start") else None,
            )
        )
    caps = response.capabilities
    return Description(
        name=foreign(response.name),
        channels=tuple(channels),
        implementation=foreign(response.implementation),
        capabilities=Capabilities(
            streaming=caps.streaming,
            variable_step_size=caps.variable_step_size,
            fixed_step_size=caps.fixed_step_size,
            step_socket=caps.step_socket,
        ),
    )


# --- Initialize ------------------------------------------------------------------------------


def initialize_to_pb(setup: RunSetup, codec: Codec) -> pb.InitializeRequest:
    """The Initialize request for ``setup``, values checked against the participant's channels."""
    request = pb.InitializeRequest(
        run_id=setup.run_id,
        run_secret=setup.run_secret,
        start_time=setup.start_time,
        step_size=setup.step_size,
        stop_time=setup.stop_time,
        lease_seconds=setup.lease,
    )
    codec.encode_into(request.parameters, setup.parameters, _PARAMETERS)
    codec.encode_into(request.inputs, setup.inputs, _INPUTS)
    return request


def initialize_from_pb(request: pb.InitializeRequest, codec: Codec) -> RunSetup:
    """The run set-up an Initialize request carries, without its secret (the runtime reads
    ``request.run_secret`` itself; participants never see it)."""
    return RunSetup(
        run_id=request.run_id,
        start_time=request.start_time,
        step_size=request.step_size,
        stop_time=request.stop_time if request.HasField("stop_time") else None,
        parameters=codec.decode(request.parameters, (Causality.PARAMETER,)),
        inputs=codec.decode(request.inputs, (Causality.INPUT,)),
        lease=request.lease_seconds,
    )


def initialize_response(outputs: Mapping[str, object], codec: Codec) -> pb.InitializeResponse:
    response = pb.InitializeResponse()
    codec.encode_into(response.outputs, outputs, _OUTPUTS)
    return response


# --- DoStep ----------------------------------------------------------------------------------


MIN_SECRET, MAX_SECRET = 16, 256
"""Bounds of a run secret's length [bytes] (InitializeRequest.run_secret)."""
SECRET_BYTES = 32
"""Length of the run secrets Coupler makes (``secrets.token_bytes``)."""


@dataclass(frozen=True, slots=True)
class RunKey:
    """What every call of a run carries after Initialize: its public id and its secret."""

    id: str = ""
    secret: bytes = field(default=b"", repr=False)


@dataclass(frozen=True, slots=True)
class Step:
    """What a DoStep request carries."""

    run_id: str
    time: float
    step: float
    inputs: dict[str, Value]


def step_to_pb(
    run: RunKey, time: float, step: float, inputs: Mapping[str, object], codec: Codec
) -> pb.DoStepRequest:
    request = pb.DoStepRequest(
        run_id=run.id, run_secret=run.secret, current_time=time, step_size=step
    )
    codec.encode_into(request.inputs, inputs, _INPUTS)
    return request


def step_from_pb(
    request: pb.DoStepRequest, codec: Codec, large: Iterable[tuple[str, bytes]] = ()
) -> Step:
    """The step a DoStep request asks for, inputs checked, with the long Binary inputs
    ``step_request`` cut out of it (``large``)."""
    inputs = codec.decode(request.inputs, _INPUTS, large)
    return Step(request.run_id, request.current_time, request.step_size, inputs)


class Pieces(list[bytes]):
    """An answer serialized as pieces whose concatenation is the message: the message without
    its long Binary outputs, then each one's binding head and the value itself (not copied).
    gRPC's serializer joins them once (``serialized``); the step socket writes them as they are
    (``answer_pieces``)."""


Answer: TypeAlias = pb.DoStepResponse | bytes | Pieces
"""An answer to a step as the participant runtime hands it to gRPC: a message, or one already
serialized (in pieces) when it carries long Binary outputs (``serialized`` sends either)."""


def serialized(answer: Answer) -> bytes:
    """The bytes gRPC sends for ``answer`` (the participant runtime's response serializer)."""
    kind = type(answer)
    if kind is bytes:
        return answer  # type: ignore[return-value]
    if kind is Pieces:
        return b"".join(answer)  # type: ignore[arg-type]
    return answer.SerializeToString()  # type: ignore[union-attr]


def answer_pieces(answer: Answer) -> list[bytes]:
    """``answer`` serialized as pieces whose concatenation is the message, its long Binary
    values not joined (what the step socket writes)."""
    if type(answer) is Pieces:
        return answer
    return [serialized(answer)]


def step_response(
    outputs: Mapping[str, object],
    codec: Codec,
    *,
    terminate_reason: str | None = None,
    cost: StepMeter | None = None,
) -> Answer:
    """The answer to a step; with ``terminate_reason`` it asks to end the run; with ``cost``
    it says what the step cost the participant (``step_seconds``, ``waited_seconds``). Long
    Binary outputs (``LARGE_BYTES`` or more) are written apart: the answer is then the message
    without them, serialized, followed by each one's binding (``step_answer`` reads either)."""
    response, large = _response_apart(outputs, codec)
    if cost is not None:
        response.step_seconds, response.waited_seconds = cost.seconds, cost.waited
    if terminate_reason is not None:
        response.terminate = True
        response.terminate_reason = terminate_reason
    return _joined(response, large) if large else response


def _response_apart(
    outputs: Mapping[str, object], codec: Codec
) -> tuple[pb.DoStepResponse, list[tuple[str, bytes]]]:
    """A DoStepResponse with the bindings of ``outputs`` but the long Binary ones, and those."""
    response = pb.DoStepResponse()
    large = codec.encode_apart(response.outputs, outputs, _OUTPUTS)
    return response, large


HELD_BYTES = 1024 * 1024
"""What String and Binary values ``StepAnswers`` sets into its prepared message in place may
add up to before the message is made anew: protobuf keeps a field's earlier values in the
message's memory until the message goes, so a message reused for ever would grow by every
value set into it [bytes]."""


class _Prepared:
    """One message whose bindings get each step's values in place while they name the same
    channels as the last step's (``StepAnswers``, ``StepRequests``): building a message and
    its bindings anew each step costs several times what setting the values costs. Once the
    String and Binary values set in place add up to ``HELD_BYTES``, the message is made anew
    (the old one's memory goes with it)."""

    def __init__(self, codec: Codec, allowed: tuple[Causality, ...]) -> None:
        self._codec = codec
        self._allowed = allowed
        self._limit = codec.limit(allowed)
        self._bindings: dict[str, tuple[pb.VariableBinding | None, _Slot]] = {}
        """Each channel's binding in the message (None: a long Binary value, written apart)."""
        self._held = 0
        """Bytes of String and Binary values set into the message in place."""

    def _fits(self, values: Mapping[str, object]) -> bool:
        """Whether the prepared bindings name the channels of ``values`` and the message may
        take more values in place."""
        return values.keys() == self._bindings.keys() and self._held <= HELD_BYTES

    def _set(self, values: Mapping[str, object]) -> list[tuple[str, bytes]] | None:
        """The values into the prepared bindings, each checked as ``Codec`` checks it, and the
        long Binary values written apart (by channel); None when the prepared message does not
        take them (a value written apart is short now, or one in place long): make it anew."""
        codec, bindings = self._codec, self._bindings
        size = held = 0
        large: list[tuple[str, bytes]] = []
        for name, value in values.items():
            binding, slot = bindings[name]
            if binding is None:  # written apart, unless it is no longer a long Binary value
                if type(value) is not bytes or len(value) < LARGE_BYTES:
                    return None
                if slot.maximum and len(value) > slot.maximum:
                    _within(slot, value)
                large.append((name, value))
                size += len(value)
                continue
            checked = codec._checked(slot, value)
            if slot.weight:
                length = len(value) * slot.weight  # type: ignore[arg-type]
                if slot.weight == 1 and length >= LARGE_BYTES:  # now long: written apart
                    return None
                if slot.maximum and length > slot.maximum:
                    _within(slot, value)  # type: ignore[arg-type]
                size += length
                held += length
            setattr(binding, slot.field, checked)
        self._held += held
        if size > self._limit:
            codec._fits(values, self._allowed)
        return large

    def _prepared(
        self, repeated: RepeatedBindings, large: Iterable[tuple[str, bytes]] = ()
    ) -> None:
        """Take the bindings of a message just built, and the long values written apart from
        it, as the prepared ones."""
        table = self._codec._table(self._allowed)
        bindings: dict[str, tuple[pb.VariableBinding | None, _Slot]] = {
            b.channel: (b, table[b.channel]) for b in repeated
        }
        bindings.update((name, (None, table[name])) for name, _ in large)
        self._bindings = bindings
        self._held = 0


class StepAnswers(_Prepared):
    """The answers to the steps of one step stream, written into one prepared message.

    The first answer is built as ``step_response`` builds it; while a step's outputs name the
    same channels as the last one's (the long Binary ones among them the same), the next answer
    is the same message with the new values set into its bindings in place, checked as
    ``Codec`` checks them, and the long Binary values written after it (``step_response``).
    Safe because a stream sends (serializes) each answer before the next is made; one object
    per stream.
    """

    def __init__(self, codec: Codec) -> None:
        super().__init__(codec, _OUTPUTS)
        self._response: pb.DoStepResponse | None = None

    def answer(self, outputs: Mapping[str, object], cost: StepMeter | None = None) -> Answer:
        """The answer carrying ``outputs`` (each checked against its channel), and what the
        step cost the participant (``cost``; else none said)."""
        response = self._response
        if response is None or not self._fits(outputs):
            return self._prepare(outputs, cost)
        large = self._set(outputs)
        if large is None:
            return self._prepare(outputs, cost)
        if cost is not None:
            response.step_seconds, response.waited_seconds = cost.seconds, cost.waited
        else:
            response.step_seconds = response.waited_seconds = 0.0
        return _joined(response, large) if large else response

    def _prepare(self, outputs: Mapping[str, object], cost: StepMeter | None) -> Answer:
        self._response = None  # until the new one is complete
        response, large = _response_apart(outputs, self._codec)
        if cost is not None:
            response.step_seconds, response.waited_seconds = cost.seconds, cost.waited
        self._prepared(response.outputs, large)
        self._response = response
        return _joined(response, large) if large else response


class StepRequests(_Prepared):
    """The requests of one run's steps (``step_pieces``), written into one prepared message as
    ``StepAnswers`` writes answers: the run's id and secret set once, each step's time, step
    size and inputs set in place while the inputs name the same channels as the last step's.
    A step with a long Binary input is made by ``step_pieces`` (its value sent apart)."""

    def __init__(self, codec: Codec, run: RunKey) -> None:
        super().__init__(codec, _INPUTS)
        self._run = run
        self._request: pb.DoStepRequest | None = None

    def pieces(self, time: float, step: float, inputs: Mapping[str, object]) -> list[bytes]:
        """``step_pieces(run, time, step, inputs, codec)``: the same message."""
        request = self._request
        if request is None or not self._fits(inputs) or self._set(inputs) is None:
            return self._prepare(time, step, inputs)
        request.current_time, request.step_size = time, step
        return [request.SerializeToString()]

    def _prepare(self, time: float, step: float, inputs: Mapping[str, object]) -> list[bytes]:
        self._request = None  # until a new one is complete
        if _long_binary(inputs):
            return step_pieces(self._run, time, step, inputs, self._codec)
        request = step_to_pb(self._run, time, step, inputs, self._codec)
        self._prepared(request.inputs)
        self._request = request
        return [request.SerializeToString()]


def _long_binary(values: Mapping[str, object]) -> bool:
    """Whether a value is a Binary one long enough to be sent apart (``step_pieces``)."""
    return any(type(v) is bytes and len(v) >= LARGE_BYTES for v in values.values())


def outputs_from_pb(
    response: pb.InitializeResponse | pb.DoStepResponse,
    codec: Codec,
    large: Iterable[tuple[str, bytes]] = (),
) -> dict[str, Value]:
    """The outputs an answer carries, with those ``step_answer`` cut out of it (``large``)."""
    return codec.decode(response.outputs, _OUTPUTS, large)


StepCost: TypeAlias = tuple[float | None, float | None]
"""What a step cost the participant by its own account, and how much of it it waited for an
outside program [s] (``DoStepResponse.step_seconds``, ``waited_seconds``); None for what it
did not say."""


def step_cost(response: pb.DoStepResponse) -> StepCost:
    """What the answer says its step cost the participant (``cost_of``)."""
    return cost_of(response.step_seconds, response.waited_seconds)


def cost_of(seconds: float, waited: float) -> StepCost:
    """The figures of an answer as reported: each None when 0 (not reported), negative or not
    finite."""
    return (
        seconds if 0 < seconds < math.inf else None,
        waited if 0 < waited < math.inf else None,
    )


def termination_requested(response: pb.DoStepResponse) -> str | None:
    """The reason when the answer asks to end the run, else None."""
    if not response.terminate:
        return None
    return foreign(response.terminate_reason) or "the participant asked to end the run"


# --- Long Binary values, not copied more than needed ------------------------------------------
#
# A camera frame (1.44 MB) would be copied three times on its way into a request (into the
# message, into its serialization, into the transport's buffer) and four times on its way out
# of an answer; and protobuf (upb) is slow at it: a fresh message with such a value set and
# serialized took 4.3 ms, a value set into a reused message 1.3 ms (and stayed in its memory).
# Protobuf's encoding lets a message be written in pieces (its fields in any order, each a key,
# a length and the bytes), so long Binary values travel apart on both sides: the native step
# channel sends a request from pieces, a value one of them as it is (``step_pieces``), and the
# participant runtime answers with the message serialized and each value joined after it once
# (``step_response``, ``StepAnswers``); each side takes such values out of the bytes it
# receives with one copy each (``step_answer``, ``step_request``); everything else is
# protobuf's own work.

LARGE_BYTES = 64 * 1024
"""A Binary value this long or longer travels apart: written into a message without protobuf
(``step_pieces``, ``step_response``), cut out of one with a copy (``step_request``,
``step_answer``)."""
_LEN = 2
"""The wire type of a length-delimited field."""


def _key(message: type[Message], name: str) -> int:
    """The key of the length-delimited field ``name`` of ``message``."""
    return int(message.DESCRIPTOR.fields_by_name[name].number) << 3 | _LEN


_INPUTS_KEY = _key(pb.DoStepRequest, "inputs")
_OUTPUTS_KEY = _key(pb.DoStepResponse, "outputs")
_CHANNEL_KEY = _key(pb.VariableBinding, "channel")
_BINARY_KEY = _key(pb.VariableBinding, "binary")


def _varint(value: int) -> bytes:
    out = bytearray()
    while value > 0x7F:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _read_varint(data: memoryview, at: int) -> tuple[int, int]:
    """The varint at ``at`` and where it ends; IndexError or ValueError when there is none."""
    value = shift = 0
    while True:
        byte = data[at]
        at += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, at
        shift += 7
        if shift > 63:
            raise ValueError("varint longer than 10 bytes")


def _apart(key: int, large: Iterable[tuple[str, bytes]]) -> list[bytes]:
    """Each long Binary value as a binding in the repeated field whose key is ``key``: its
    key, lengths and channel as one piece, then the value itself (the same object)."""
    pieces: list[bytes] = []
    for name, value in large:
        channel = name.encode()
        head = (
            _varint(_CHANNEL_KEY)
            + _varint(len(channel))
            + channel
            + _varint(_BINARY_KEY)
            + _varint(len(value))
        )
        pieces += [_varint(key) + _varint(len(head) + len(value)) + head, value]
    return pieces


def _joined(response: pb.DoStepResponse, large: Iterable[tuple[str, bytes]]) -> Pieces:
    """``response`` serialized with the long Binary outputs ``large`` after it, in pieces
    (joined once at most, ``serialized``): protobuf would copy each value twice (into the
    message, out of it)."""
    return Pieces([response.SerializeToString(), *_apart(_OUTPUTS_KEY, large)])


def step_pieces(
    run: RunKey, time: float, step: float, inputs: Mapping[str, object], codec: Codec
) -> list[bytes]:
    """``step_to_pb``'s request serialized as pieces whose concatenation is the message: the
    request without its long Binary inputs, then for each of them a binding's key, lengths and
    channel, and the value itself (the same object, not copied)."""
    request = pb.DoStepRequest(
        run_id=run.id, run_secret=run.secret, current_time=time, step_size=step
    )
    large = codec.encode_apart(request.inputs, inputs, _INPUTS)
    return [request.SerializeToString(), *_apart(_INPUTS_KEY, large)]


StepRequest: TypeAlias = tuple[pb.DoStepRequest, list[tuple[str, bytes]]]
"""A DoStep request as the participant runtime receives it (``step_request``): the message
without its long Binary inputs, and those by channel."""


def step_request(data: bytes | bytearray | memoryview) -> StepRequest:
    """A serialized DoStepRequest parsed, its long Binary inputs cut out with one copy each (by
    channel; ``step_from_pb`` takes them): the participant runtime's request deserializer.
    Protobuf would copy them into the message and again out of it."""
    return _parsed(pb.DoStepRequest, _INPUTS_KEY, data)


def step_answer(data: bytes | memoryview) -> tuple[pb.DoStepResponse, list[tuple[str, bytes]]]:
    """A serialized DoStepResponse parsed, its long Binary outputs cut out with one copy each
    (by channel; ``outputs_from_pb`` takes them): protobuf would copy them into the message
    and again out of it."""
    return _parsed(pb.DoStepResponse, _OUTPUTS_KEY, data)


_M = TypeVar("_M", pb.DoStepRequest, pb.DoStepResponse)


def _parsed(
    message: type[_M], key: int, data: bytes | bytearray | memoryview
) -> tuple[_M, list[tuple[str, bytes]]]:
    """``data`` parsed as ``message``, the long Binary values of its bindings in the field of
    key ``key`` cut out. A message that is not as expected is left whole to protobuf, which
    parses it or says what is wrong."""
    if len(data) < LARGE_BYTES:
        return message.FromString(bytes(data) if type(data) is not bytes else data), []
    view = memoryview(data)
    try:
        rest, large = _cut(view, key)
    except (IndexError, ValueError):
        rest, large = bytes(view), []
    return message.FromString(rest), large


def _cut(data: memoryview, field: int) -> tuple[bytes, list[tuple[str, bytes]]]:
    """``data`` without its bindings (field key ``field``) that carry a long Binary value, and
    those values."""
    kept: list[memoryview] = []
    large: list[tuple[str, bytes]] = []
    start = 0
    for key, at, body, after in _fields(data):
        if key == field and after - body >= LARGE_BYTES:
            binding = _binary_binding(data[body:after])
            if binding is not None:
                kept.append(data[start:at])
                large.append(binding)
                start = after
    kept.append(data[start:])
    return b"".join(kept), large


def _fields(data: memoryview) -> Iterator[tuple[int, int, int, int]]:
    """The top-level fields of a serialized message, in order: each one's key, where it
    starts, where its value starts (a length-delimited one's after its length) and where it
    ends. ValueError for a group or a truncated message."""
    at = 0
    while at < len(data):
        key, body = _read_varint(data, at)
        kind = key & 7
        if kind == _LEN:
            size, body = _read_varint(data, body)
            after = body + size
        elif kind == 0:
            after = _read_varint(data, body)[1]
        elif kind in (1, 5):
            after = body + (8 if kind == 1 else 4)
        else:
            raise ValueError("a group")
        if after > len(data):
            raise ValueError("truncated")
        yield key, at, body, after
        at = after


def _binary_binding(data: memoryview) -> tuple[str, bytes] | None:
    """The channel and value of a serialized VariableBinding made of a channel and a Binary
    value only (each once); None for any other."""
    fields: dict[int, memoryview] = {}
    at = 0
    while at < len(data):
        key, body = _read_varint(data, at)
        if key not in (_CHANNEL_KEY, _BINARY_KEY) or key in fields:
            return None
        size, body = _read_varint(data, body)
        at = body + size
        if at > len(data):
            return None
        fields[key] = data[body:at]
    if len(fields) != 2:
        return None
    try:
        name = str(fields[_CHANNEL_KEY], "utf-8")
    except UnicodeDecodeError:
        return None
    return name, bytes(fields[_BINARY_KEY])


def step_socket_end(code: int, message: str) -> bytes:
    """The serialized StepSocketEnd a participant's step socket ends with (``code``: a gRPC
    status code number)."""
    return pb.StepSocketEnd(code=code, message=message).SerializeToString()


# --- Terminate -------------------------------------------------------------------------------


def terminate_to_pb(run: RunKey, reason: str) -> pb.TerminateRequest:
    return pb.TerminateRequest(run_id=run.id, run_secret=run.secret, reason=reason)
