"""Plain Python values of channels: checking, parsing text, coercing raw values, widening.

The one place where a value is made to fit its channel type. Every caller uses it: SSP
parameter files and ``--param`` texts (``parse``), FMU and simulator values (``coerce``),
Integer outputs feeding Real inputs (``widen``), values arriving over the wire (``check``).
Protobuf lives in ``coupler.wire``; nothing here imports it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from coupler.channels import Channel, Value, ValueType
from coupler.errors import ChannelValueError

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
MAX_MESSAGE_BYTES = 64 * 1024 * 1024
"""Default message limit [bytes]: the Binary and String values of one message together (an
800 x 600 RGB frame is 1.44 MB). ``coupler.wire.Codec`` checks it; docs/protocol.md
"Message size"."""

_TRUE, _FALSE = ("true", "1"), ("false", "0")


@dataclass(frozen=True, kw_only=True)
class ValuePolicy:
    """Limits applied to values on top of their type."""

    allow_nonfinite: bool = False
    """Accept NaN and +/-Inf on Real channels."""
    max_message_bytes: int = MAX_MESSAGE_BYTES
    """Largest sum of the Binary and String values of one message [bytes] when one of its
    Binary or String channels declares no maximum (``Channel.max_bytes``); with every one
    declared, their sum (``message_limit``). ``coupler.wire`` checks it per message, naming
    the largest channel."""
    cap_declared: bool = False
    """Declared maxima count up to ``max_message_bytes`` at most: the orchestrator's
    ``--max-message-size`` is a cap the user raises, where a participant's own declarations
    stand."""


DEFAULT_POLICY = ValuePolicy()


def message_limit(channels: Iterable[Channel], policy: ValuePolicy = DEFAULT_POLICY) -> int:
    """Bytes the Binary and String values of one message on ``channels`` may have together:
    the sum of their declared maxima when there are such channels and each of them declares
    one (at most the policy's ``max_message_bytes`` with ``cap_declared``), else the policy's
    ``max_message_bytes`` (a message of numbers only keeps the default: it declares nothing)."""
    sized = [c for c in channels if c.sized]
    if not sized or any(c.max_bytes <= 0 for c in sized):
        return policy.max_message_bytes
    total = sum(c.max_bytes for c in sized)
    return min(total, policy.max_message_bytes) if policy.cap_declared else total


def check(channel: Channel, value: object, policy: ValuePolicy = DEFAULT_POLICY) -> Value:
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
    return bytes(value)


def parse(kind: ValueType, text: str) -> Value:
    """The value of ``kind`` written as ``text`` (SSP/FMI attribute syntax); ValueError if not.

    Real: a decimal number (``inf``/``nan`` too; ``check`` applies the finite policy);
    Integer and Enumeration: a whole number; Boolean: ``true``/``false``/``1``/``0``;
    String: the text itself; Binary: hexadecimal digits.
    """
    if kind is ValueType.REAL:
        return float(text)
    if kind in (ValueType.INTEGER, ValueType.ENUMERATION):
        return int(text.strip())
    if kind is ValueType.BOOLEAN:
        word = text.strip().lower()
        if word in _TRUE:
            return True
        if word in _FALSE:
            return False
        raise ValueError(f"{text!r} is not a Boolean; write true or false")
    if kind is ValueType.BINARY:
        return bytes.fromhex(text)
    return text


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


def widen(kind: ValueType, value: Value) -> Value:
    """An Integer ``value`` as a Real when ``kind`` is Real (the only implicit type change)."""
    if kind is ValueType.REAL and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def type_name(value: object) -> str:
    """The channel type name of a Python value, for messages."""
    names = {bool: "Boolean", int: "Integer", float: "Real", str: "String", bytes: "Binary"}
    return names.get(type(value), type(value).__name__)


def _mismatch(channel: Channel, value: object) -> ChannelValueError:
    return ChannelValueError(
        f"channel '{channel.name}' expects {channel.type}, got {type_name(value)} {value!r:.60}",
        channel=channel.name,
        expected=str(channel.type),
    )
