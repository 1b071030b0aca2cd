"""Values between mosaik and Coupler: one place that says how each channel type travels.

mosaik moves JSON values (over TCP) or Python objects (in process) and has no types of its own:
Real, Integer, Boolean and String travel as JSON numbers, booleans and strings; a Binary value
travels as base64 text (JSON has no bytes). What comes from mosaik is converted to the channel's
type (an Integer 3 for a Real channel is 3.0; numpy numbers are plain numbers) or refused with a
``ChannelValueError`` naming the channel.
"""

from __future__ import annotations

import base64
import binascii
from typing import Any

from coupler.channels import Channel, Value, ValueType
from coupler.errors import ChannelValueError
from coupler.values import check, coerce


def to_mosaik(channel: Channel, value: Value) -> Any:
    """A Coupler value as mosaik carries it (Binary: base64 text)."""
    if channel.type is ValueType.BINARY:
        return base64.b64encode(bytes(value)).decode("ascii")
    return value


def from_mosaik(channel: Channel, raw: Any) -> Value:
    """A value mosaik gave for ``channel``, as the channel's type; ChannelValueError if it
    cannot be one."""
    try:
        if channel.type is ValueType.BINARY and isinstance(raw, str):
            return base64.b64decode(raw, validate=True)
        if hasattr(raw, "item") and not isinstance(raw, bytes | str):  # numpy scalars
            raw = raw.item()
        if channel.type is ValueType.REAL and isinstance(raw, int) and not isinstance(raw, bool):
            raw = float(raw)
        integral = channel.type in (ValueType.INTEGER, ValueType.ENUMERATION)
        if integral and isinstance(raw, float) and raw.is_integer():
            raw = int(raw)
        if channel.type is ValueType.STRING and raw is not None and not isinstance(raw, str):
            raw = coerce(ValueType.STRING, raw)
        return check(channel, raw)
    except (binascii.Error, ValueError, TypeError) as exc:
        raise ChannelValueError(
            f"channel '{channel.name}' expects {channel.type}, got {raw!r:.60} from mosaik ({exc})",
            channel=channel.name,
            expected=str(channel.type),
        ) from exc
