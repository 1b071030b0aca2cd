"""Python values <-> protobuf messages. The only module that touches ``coupler.v1`` messages.

Every value is checked against its channel's description: the type, the int32 range, the
NaN/Inf policy and a size limit for binary values. Errors name the channel and what it expects.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from google.protobuf import json_format, message_factory
from google.protobuf.descriptor_pool import Default as default_pool
from google.protobuf.message import DecodeError, Message

from coupler.channels import (
    Capabilities,
    Causality,
    Channel,
    Description,
    RunSetup,
    Value,
    ValueType,
)
from coupler.errors import ChannelValueError
from coupler.v1 import component_pb2 as pb
from coupler.v1 import railway_pb2

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
DEFAULT_MAX_BINARY_BYTES = 4 * 1024 * 1024

_FIELD_OF_TYPE = {
    ValueType.REAL: "real",
    ValueType.INTEGER: "integer",
    ValueType.ENUMERATION: "integer",
    ValueType.BOOLEAN: "boolean",
    ValueType.STRING: "text",
    ValueType.BINARY: "binary",
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
_RAILWAY_MESSAGES = railway_pb2.DESCRIPTOR.message_types_by_name  # registers them in the pool


@dataclass(frozen=True, kw_only=True)
class ValuePolicy:
    """Limits applied to values on top of their type."""

    allow_nonfinite: bool = False
    """Accept NaN and +/-Inf on Real channels."""
    max_binary_bytes: int = DEFAULT_MAX_BINARY_BYTES
    """Largest binary value accepted [bytes]."""


def check(channel: Channel, value: object, policy: ValuePolicy = ValuePolicy()) -> Value:
    """``value`` as the Python value ``channel`` carries, or ChannelValueError naming it."""
    kind = channel.type
    if kind is ValueType.REAL:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _mismatch(channel, value)
        real = float(value)
        if not policy.allow_nonfinite and not math.isfinite(real):
            raise ChannelValueError(
                f"channel '{channel.name}' expects a finite Real, got {real!r}",
                channel=channel.name,
                expected="finite Real",
            )
        return real
    if kind in (ValueType.INTEGER, ValueType.ENUMERATION):
        if isinstance(value, bool) or not isinstance(value, int):
            raise _mismatch(channel, value)
        if not INT32_MIN <= value <= INT32_MAX:
            raise ChannelValueError(
                f"channel '{channel.name}' expects {kind} within int32 "
                f"[{INT32_MIN}, {INT32_MAX}], got {value}",
                channel=channel.name,
                expected=str(kind),
            )
        return value
    if kind is ValueType.BOOLEAN:
        if not isinstance(value, bool):
            raise _mismatch(channel, value)
        return value
    if kind is ValueType.STRING:
        if not isinstance(value, str):
            raise _mismatch(channel, value)
        return value
    if not isinstance(value, bytes | bytearray):
        raise _mismatch(channel, value)
    if len(value) > policy.max_binary_bytes:
        raise ChannelValueError(
            f"channel '{channel.name}' carries at most {policy.max_binary_bytes} bytes, "
            f"got {len(value)}",
            channel=channel.name,
            expected="Binary",
        )
    return bytes(value)


def coerce(kind: ValueType, raw: Any) -> Value:
    """``raw`` (a simulator's or FMU's own representation) as the Python value of ``kind``."""
    if kind is ValueType.REAL:
        return float(raw)
    if kind in (ValueType.INTEGER, ValueType.ENUMERATION):
        return int(raw)
    if kind is ValueType.BOOLEAN:
        return bool(raw)
    if kind is ValueType.STRING:
        return raw.decode("utf-8") if isinstance(raw, bytes) else str(raw or "")
    return bytes(raw)


def _mismatch(channel: Channel, value: object) -> ChannelValueError:
    return ChannelValueError(
        f"channel '{channel.name}' expects {channel.type}, got {_type_name(value)} {value!r:.60}",
        channel=channel.name,
        expected=str(channel.type),
    )


def _type_name(value: object) -> str:
    names = {bool: "Boolean", int: "Integer", float: "Real", str: "String", bytes: "Binary"}
    return names.get(type(value), type(value).__name__)


class Codec:
    """Encodes and decodes the bindings of one participant, checked against its channels."""

    def __init__(self, description: Description, policy: ValuePolicy = ValuePolicy()) -> None:
        self.description = description
        self.policy = policy
        self._channels = {c.name: c for c in description.channels}

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

    def encode(
        self, values: Mapping[str, object], allowed: Iterable[Causality] | None = None
    ) -> list[pb.VariableBinding]:
        """Bindings for ``values``, each checked against its channel."""
        allowed = tuple(allowed) if allowed is not None else None
        return [self.binding(self.channel(n, allowed), v) for n, v in values.items()]

    def binding(self, channel: Channel, value: object) -> pb.VariableBinding:
        """One checked binding."""
        checked = check(channel, value, self.policy)
        binding = pb.VariableBinding(channel=channel.name)
        setattr(binding, _FIELD_OF_TYPE[channel.type], checked)
        return binding

    def decode(
        self, bindings: Iterable[pb.VariableBinding], allowed: Iterable[Causality] | None = None
    ) -> dict[str, Value]:
        """Python values of ``bindings``, each checked against its channel."""
        allowed = tuple(allowed) if allowed is not None else None
        values: dict[str, Value] = {}
        for binding in bindings:
            channel = self.channel(binding.channel, allowed)
            field = binding.WhichOneof("value")
            expected = _FIELD_OF_TYPE[channel.type]
            if field != expected:
                raise ChannelValueError(
                    f"channel '{channel.name}' expects {channel.type}, got {_binding_kind(field)}",
                    channel=channel.name,
                    expected=str(channel.type),
                )
            values[channel.name] = check(channel, getattr(binding, field), self.policy)
        return values


def _binding_kind(field: str | None) -> str:
    kinds = {
        "real": "Real",
        "integer": "Integer",
        "boolean": "Boolean",
        "text": "String",
        "binary": "Binary",
    }
    return kinds.get(field or "", "no value")


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


# --- messages of the protocol ---------------------------------------------------------------


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
        ),
        channels=[
            pb.ChannelDescription(
                name=c.name,
                causality=_CAUSALITY_TO_PB[c.causality],
                type=_TYPE_TO_PB[c.type],
                unit=c.unit,
                description=c.description,
                message_type=c.message_type,
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
                name=c.name,
                causality=_CAUSALITY_FROM_PB[c.causality],
                type=_TYPE_FROM_PB[c.type],
                unit=c.unit,
                description=c.description,
                message_type=c.message_type,
                start=_untyped_value(c.start) if c.HasField("start") else None,
            )
        )
    caps = response.capabilities
    return Description(
        name=response.name,
        channels=tuple(channels),
        implementation=response.implementation,
        capabilities=Capabilities(
            streaming=caps.streaming,
            variable_step_size=caps.variable_step_size,
            fixed_step_size=caps.fixed_step_size,
        ),
    )


def initialize_to_pb(setup: RunSetup, codec: Codec) -> pb.InitializeRequest:
    """The Initialize request for ``setup``, values checked against the participant's channels."""
    return pb.InitializeRequest(
        run_id=setup.run_id,
        start_time=setup.start_time,
        step_size=setup.step_size,
        stop_time=setup.stop_time,
        parameters=codec.encode(setup.parameters, (Causality.PARAMETER,)),
        inputs=codec.encode(setup.inputs, (Causality.INPUT,)),
    )


def initialize_from_pb(request: pb.InitializeRequest, codec: Codec) -> RunSetup:
    """The run set-up an Initialize request carries."""
    return RunSetup(
        run_id=request.run_id,
        start_time=request.start_time,
        step_size=request.step_size,
        stop_time=request.stop_time if request.HasField("stop_time") else None,
        parameters=codec.decode(request.parameters, (Causality.PARAMETER,)),
        inputs=codec.decode(request.inputs, (Causality.INPUT,)),
    )


def initialize_response(outputs: Mapping[str, object], codec: Codec) -> pb.InitializeResponse:
    return pb.InitializeResponse(outputs=codec.encode(outputs, (Causality.OUTPUT,)))


def step_to_pb(
    time: float, step: float, inputs: Mapping[str, object], codec: Codec
) -> pb.DoStepRequest:
    return pb.DoStepRequest(
        current_time=time, step_size=step, inputs=codec.encode(inputs, (Causality.INPUT,))
    )


def step_from_pb(request: pb.DoStepRequest, codec: Codec) -> tuple[float, float, dict[str, Value]]:
    """(time, step, inputs) of a DoStep request."""
    inputs = codec.decode(request.inputs, (Causality.INPUT,))
    return request.current_time, request.step_size, inputs


def step_response(outputs: Mapping[str, object], codec: Codec) -> pb.DoStepResponse:
    return pb.DoStepResponse(outputs=codec.encode(outputs, (Causality.OUTPUT,)))


def outputs_from_pb(
    response: pb.InitializeResponse | pb.DoStepResponse, codec: Codec
) -> dict[str, Value]:
    return codec.decode(response.outputs, (Causality.OUTPUT,))


def terminate_to_pb(reason: str) -> pb.TerminateRequest:
    return pb.TerminateRequest(reason=reason)


def terminate_reason(request: pb.TerminateRequest) -> str:
    return request.reason


# --- structured values in binary channels ----------------------------------------------------


def _message_class(message_type: str) -> type[Message]:
    try:
        descriptor = default_pool().FindMessageTypeByName(message_type)
    except KeyError as exc:
        raise ChannelValueError(
            f"unknown protobuf message type '{message_type}' "
            f"(known railway messages: {', '.join(sorted(_RAILWAY_MESSAGES))})",
            channel="",
            expected=message_type,
        ) from exc
    return message_factory.GetMessageClass(descriptor)


def encode_message(message_type: str, fields: Mapping[str, Any]) -> bytes:
    """Serialize a message given by its full name (``coupler.v1.TrainState``) from a dict."""
    message = _message_class(message_type)()
    try:
        json_format.ParseDict(dict(fields), message)
    except json_format.ParseError as exc:
        raise ChannelValueError(
            f"fields do not fit {message_type}: {exc}", channel="", expected=message_type
        ) from exc
    return message.SerializeToString(deterministic=True)


def decode_message(message_type: str, data: bytes) -> dict[str, Any]:
    """A dict (proto field names, every field present) of a serialized message."""
    message = _message_class(message_type)()
    try:
        message.ParseFromString(data)
    except DecodeError as exc:
        raise ChannelValueError(
            f"bytes are not a valid {message_type}: {exc}", channel="", expected=message_type
        ) from exc
    return json_format.MessageToDict(
        message, preserving_proto_field_name=True, always_print_fields_with_no_presence=True
    )
