from __future__ import annotations

import math

import pytest

from coupler import values
from coupler.channels import Causality, Channel, Description, ValueType
from coupler.errors import ChannelValueError

REAL = Channel(name="speed", causality=Causality.OUTPUT, type=ValueType.REAL, unit="m/s")
INT = Channel(name="count", causality=Causality.OUTPUT, type=ValueType.INTEGER)
BIN = Channel(name="blob", causality=Causality.INPUT, type=ValueType.BINARY)


@pytest.mark.parametrize(
    ("channel", "value", "expected"),
    [
        (REAL, 1, 1.0),
        (REAL, 2.5, 2.5),
        (INT, 2**31 - 1, 2**31 - 1),
        (INT, -(2**31), -(2**31)),
        (BIN, bytearray(b"ab"), b"ab"),
    ],
)
def test_check_accepts_and_normalises(channel: Channel, value: object, expected: object) -> None:
    assert values.check(channel, value) == expected


@pytest.mark.parametrize(
    ("channel", "value", "message"),
    [
        (REAL, True, "channel 'speed' expects Real, got Boolean"),
        (REAL, "1.0", "channel 'speed' expects Real, got String"),
        (REAL, math.nan, "channel 'speed' expects a finite Real, got nan"),
        (REAL, math.inf, "channel 'speed' expects a finite Real, got inf"),
        (INT, 2**31, "channel 'count' expects Integer within int32"),
        (INT, 1.0, "channel 'count' expects Integer, got Real"),
        (BIN, "text", "channel 'blob' expects Binary, got String"),
    ],
)
def test_check_rejects_naming_channel_and_type(
    channel: Channel, value: object, message: str
) -> None:
    with pytest.raises(ChannelValueError, match=message.replace("(", r"\(")) as info:
        values.check(channel, value)
    assert info.value.channel == channel.name


def test_nonfinite_allowed_by_policy() -> None:
    policy = values.ValuePolicy(allow_nonfinite=True)
    assert math.isinf(float(values.check(REAL, math.inf, policy)))


def test_binary_size_limit() -> None:
    policy = values.ValuePolicy(max_binary_bytes=4)
    with pytest.raises(ChannelValueError, match="carries at most 4 bytes, got 5"):
        values.check(BIN, b"12345", policy)


def test_codec_rejects_unknown_and_wrong_causality() -> None:
    codec = values.Codec(Description(name="P", channels=(REAL, INT, BIN)))
    with pytest.raises(ChannelValueError, match=r"has no channel 'sped'.*speed"):
        codec.encode({"sped": 1.0})
    with pytest.raises(ChannelValueError, match="has no input channel 'speed'"):
        codec.encode({"speed": 1.0}, (Causality.INPUT,))


def test_description_round_trips() -> None:
    description = Description(
        name="P",
        channels=(
            REAL,
            Channel(name="n", causality=Causality.INPUT, type=ValueType.ENUMERATION, start=3),
            Channel(
                name="state",
                causality=Causality.OUTPUT,
                type=ValueType.BINARY,
                message_type="coupler.v1.TrainState",
            ),
        ),
        implementation="test",
    )
    assert values.description_from_pb(values.description_to_pb(description)) == description


def test_nested_message_round_trips() -> None:
    reading = {
        "time_s": 12.5,
        "balise_id": 101,
        "group_id": 10,
        "position_in_group": 2,
        "distance_m": 1234.5,
        "position": {"latitude_deg": 50.57, "longitude_deg": 13.01, "altitude_m": 0.0},
    }
    data = values.encode_message("coupler.v1.BaliseReading", reading)
    assert values.decode_message("coupler.v1.BaliseReading", data) == reading


def test_unknown_message_type_is_named() -> None:
    with pytest.raises(
        ChannelValueError, match=r"unknown protobuf message type 'coupler\.v1\.Nope'"
    ):
        values.encode_message("coupler.v1.Nope", {})
