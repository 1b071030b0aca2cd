from __future__ import annotations

import itertools
import math
import os
from dataclasses import replace

import pytest
from google.protobuf import source_context_pb2
from google.protobuf.message import DecodeError
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from coupler import messages, values, wire
from coupler.channels import Causality, Channel, Description, ValueType, fits_fixed_step
from coupler.errors import ChannelValueError, MessageTooLarge, ValueTooLarge
from coupler.v1.sensors_pb2 import CameraIntrinsics, Image

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


def test_message_size_limit_names_the_largest_channel() -> None:
    """The Binary and String values of one message together, both ways."""
    label = Channel(name="label", causality=Causality.OUTPUT, type=ValueType.STRING)
    codec = wire.Codec(
        Description(name="P", channels=(REAL, BIN, label)), values.ValuePolicy(max_message_bytes=8)
    )
    assert codec.decode(codec.encode({"speed": 1.0, "blob": b"1234", "label": "abcd"}))
    with pytest.raises(MessageTooLarge) as info:
        codec.encode({"blob": b"12345", "label": "äbcd"})
    assert (info.value.channel, info.value.size, info.value.total) == ("blob", 5, 10)
    assert str(info.value).startswith(
        "input 'blob' carries 5 bytes, 10 bytes with the message's other values: over the "
        "message limit of 8 bytes (7.62939e-06 MiB); raise the limit"
    )
    assert info.value.naming("Cam").startswith("input Cam.blob carries 5 bytes")
    bindings = wire.Codec(Description(name="P", channels=(BIN,))).encode({"blob": b"123456789"})
    with pytest.raises(MessageTooLarge, match="'blob' carries 9 bytes: over"):
        codec.decode(bindings)


def test_codec_rejects_unknown_and_wrong_causality() -> None:
    codec = wire.Codec(Description(name="P", channels=(REAL, INT, BIN)))
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
                max_bytes=128,
            ),
        ),
        implementation="test",
    )
    assert wire.description_from_pb(wire.description_to_pb(description)) == description
    assert wire.description_to_pb(description).channels[2].max_bytes == 128


def test_registered_message_round_trips_and_reads_as_json() -> None:
    """The registry knows only what was registered; the core registers no domain message."""
    name = "google.protobuf.SourceContext"
    assert not messages.known(name)
    messages.register(source_context_pb2.SourceContext)
    data = messages.encode_message(name, {"file_name": "Zwönitz.proto"})
    assert messages.decode_message(name, data) == {"file_name": "Zwönitz.proto"}
    assert messages.message_json(name, data) == '{"file_name":"Zwönitz.proto"}'


def test_unknown_message_type_is_named() -> None:
    with pytest.raises(
        ChannelValueError, match=r"unknown protobuf message type 'coupler\.v1\.Nope'"
    ):
        messages.encode_message("coupler.v1.Nope", {})


FUZZ = settings(
    max_examples=int(os.environ.get("COUPLER_FUZZ_EXAMPLES", "150")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
DOUBLES = st.floats(allow_nan=True, allow_infinity=True)
HEADERS = st.builds(
    Image,
    sensor=st.text(max_size=20),
    time_s=DOUBLES,
    width=st.integers(0, 2**32 - 1),
    height=st.integers(0, 2**32 - 1),
    encoding=st.text(max_size=20),
    intrinsics=st.none() | st.builds(CameraIntrinsics, fx=DOUBLES, fy=DOUBLES, cx=DOUBLES),
    max_distance_m=DOUBLES,
)
"""``coupler.v1.Image`` headers: every field but ``data`` (field 8, its highest)."""


@FUZZ
@given(HEADERS, st.binary(max_size=300), st.lists(st.integers(0, 300), max_size=4))
def test_a_message_with_its_bytes_apart_is_protobufs_message(
    header: Image, data: bytes, cuts: list[int]
) -> None:
    """``with_bytes`` (a header serialized, the pixels after it, in pieces) writes the bytes
    protobuf writes for the whole Image; ``without_bytes`` reads them back into the header and
    a view of the pixels."""
    whole = Image()
    whole.CopyFrom(header)
    whole.data = data
    bounds = [0, *sorted(min(c, len(data)) for c in cuts), len(data)]
    pieces = [data[a:b] for a, b in itertools.pairwise(bounds)]
    written = messages.with_bytes(header, "data", *pieces)
    assert written == whole.SerializeToString(deterministic=True) == whole.SerializeToString()
    read, pixels = messages.without_bytes(Image, written, "data")
    assert read.SerializeToString() == header.SerializeToString() and bytes(pixels) == data


@FUZZ
@given(st.binary(max_size=200) | st.builds(lambda h, d, tail: messages.with_bytes(h, "data", d)
                                         + tail, HEADERS, st.binary(max_size=50),
                                         st.binary(max_size=12)))  # fmt: skip
@example(b"\x42\x02ab\x0a\x01s\x42\x01c")  # data twice (the last wins), around a sensor
@example(b"\x40\x01\x0a\x01s")  # field 8 as a varint: not the bytes field protobuf knows
@example(b"\x98\x06\x07\x42\x01c")  # an unknown field, kept
@example(b"\x42\x05ab")  # truncated
@example(b"\x0a\x01\xff\x42\x01c")  # a sensor name that is not UTF-8
def test_reading_a_message_without_its_bytes_is_protobufs_reading(data: bytes) -> None:
    """Whatever the bytes, ``without_bytes`` gives what protobuf's parsing gives (the bytes
    field last written wins, unknown fields kept), or protobuf's DecodeError."""
    try:
        parsed = Image.FromString(data)
    except DecodeError:
        with pytest.raises(DecodeError):
            messages.without_bytes(Image, data, "data")
        return
    read, pixels = messages.without_bytes(Image, data, "data")
    assert bytes(pixels) == parsed.data
    parsed.ClearField("data")
    assert read.SerializeToString() == parsed.SerializeToString()


@pytest.mark.parametrize(
    ("kind", "text", "expected"),
    [
        (ValueType.REAL, "2.5e3", 2500.0),
        (ValueType.REAL, "-inf", -math.inf),
        (ValueType.INTEGER, " 42 ", 42),
        (ValueType.ENUMERATION, "3", 3),
        (ValueType.BOOLEAN, "true", True),
        (ValueType.BOOLEAN, "0", False),
        (ValueType.BOOLEAN, "False", False),
        (ValueType.STRING, " as is ", " as is "),
        (ValueType.BINARY, "00ff", b"\x00\xff"),
    ],
)
def test_parse_reads_attribute_text(kind: ValueType, text: str, expected: object) -> None:
    assert values.parse(kind, text) == expected


@pytest.mark.parametrize(
    ("kind", "text"),
    [
        (ValueType.REAL, "fast"),
        (ValueType.INTEGER, "1.5"),
        (ValueType.BOOLEAN, "yes"),
        (ValueType.BINARY, "xyz"),
    ],
)
def test_parse_refuses_what_is_not_the_type(kind: ValueType, text: str) -> None:
    with pytest.raises(ValueError):
        values.parse(kind, text)


def test_widen_turns_integers_into_reals_only_for_real_channels() -> None:
    assert values.widen(ValueType.REAL, 3) == 3.0
    assert isinstance(values.widen(ValueType.REAL, 3), float)
    assert values.widen(ValueType.INTEGER, 3) == 3
    assert values.widen(ValueType.REAL, True) is True


def test_fits_fixed_step_means_whole_multiples() -> None:
    assert fits_fixed_step(0.1, 0.05) and fits_fixed_step(0.3, 0.1) and fits_fixed_step(1.0, 0)
    assert not fits_fixed_step(0.1, 0.2)
    assert not fits_fixed_step(0.15, 0.1)


EVERY = Description(
    name="P",
    channels=(
        REAL,
        INT,
        BIN,
        Channel(name="on", causality=Causality.OUTPUT, type=ValueType.BOOLEAN),
        Channel(name="label", causality=Causality.OUTPUT, type=ValueType.STRING),
        Channel(name="mode", causality=Causality.OUTPUT, type=ValueType.ENUMERATION),
        Channel(name="data", causality=Causality.OUTPUT, type=ValueType.BINARY),
    ),
)
OUTPUTS = {"speed": 1, "count": -3, "on": True, "label": "ä", "mode": 2, "data": bytearray(b"x")}
"""Every output type, two of them in a type ``check`` converts (int -> Real, bytearray)."""


def test_a_step_answer_is_what_encode_makes() -> None:
    """``step_response`` (bindings added into the message) and ``StepAnswers`` (one prepared
    message, values set in place) give the bytes of the bindings ``Codec.encode`` makes."""
    codec = wire.Codec(EVERY)
    expected = wire.DoStepResponse(outputs=codec.encode(OUTPUTS)).SerializeToString()
    assert wire.step_response(OUTPUTS, codec).SerializeToString() == expected
    answers = wire.StepAnswers(codec)
    assert answers.answer(OUTPUTS).SerializeToString() == expected
    changed = {**OUTPUTS, "speed": 2.5, "label": "b", "data": b""}
    again = answers.answer(changed)
    assert codec.decode(again.outputs) == {**changed, "data": b""}
    assert again.SerializeToString() == wire.step_response(changed, codec).SerializeToString()
    fewer = answers.answer({"speed": 3.0})  # other channels: a message of its own
    assert codec.decode(fewer.outputs) == {"speed": 3.0}
    assert codec.decode(answers.answer(OUTPUTS).outputs) == codec.decode(codec.encode(OUTPUTS))


INPUTS = Description(
    name="Q",
    channels=(
        BIN,
        Channel(name="u", causality=Causality.INPUT, type=ValueType.REAL),
        Channel(name="n", causality=Causality.INPUT, type=ValueType.INTEGER),
        Channel(name="text", causality=Causality.INPUT, type=ValueType.STRING),
    ),
)


def test_step_requests_are_what_step_pieces_makes() -> None:
    """``StepRequests`` (one prepared request, the time and inputs set in place) gives the
    pieces ``step_pieces`` gives at every step: the same channels, others, a long Binary input
    sent apart, and back; a wrong input is refused naming its channel, in place too."""
    codec, run = wire.Codec(INPUTS), wire.RunKey("run-1", bytes(32))
    requests = wire.StepRequests(codec, run)
    long = bytes(range(256)) * (wire.LARGE_BYTES // 256 + 1)
    steps = [
        (0.0, 0.5, {"u": 1, "n": 3, "text": "a,b", "blob": b"x"}),
        (0.5, 0.5, {"u": -0.0, "n": -7, "text": "", "blob": bytearray(b"yz")}),
        (1.0, 0.25, {"u": 2.5}),
        (1.25, 0.25, {"u": 3.5}),
        (1.5, 0.25, {"u": 3.5, "n": 0, "text": "\u00fc", "blob": long}),
        (1.75, 0.25, {"u": 3.5, "n": 1, "text": "c", "blob": b""}),
        (2.0, 0.25, {"u": 3.5, "n": 1, "text": "c", "blob": b"w"}),
    ]
    for time, step, inputs in steps:
        assert requests.pieces(time, step, inputs) == wire.step_pieces(
            run, time, step, inputs, codec
        ), (time, inputs)
    for wrong, message in [
        ({"u": math.inf, "n": 1, "text": "c", "blob": b"w"}, "expects a finite Real"),
        ({"u": 1.0, "n": 2**31, "text": "c", "blob": b"w"}, "within int32"),
        ({"u": 1.0, "n": 1, "text": "c", "nope": b"w"}, "has no channel 'nope'"),
    ]:
        with pytest.raises(ChannelValueError, match=message):
            requests.pieces(2.25, 0.25, wrong)
    assert requests.pieces(2.25, 0.25, steps[-1][2]) == wire.step_pieces(
        run, 2.25, 0.25, steps[-1][2], codec
    )


@pytest.mark.parametrize(
    ("values_", "message"),
    [
        ({"speed": math.nan}, "channel 'speed' expects a finite Real, got nan"),
        ({"speed": True}, "channel 'speed' expects Real, got Boolean"),
        ({"count": 2**31}, "channel 'count' expects Integer within int32"),
        ({"count": 1.0}, "channel 'count' expects Integer, got Real"),
        ({"on": 1}, "channel 'on' expects Boolean, got Integer"),
        ({"label": b"x"}, "channel 'label' expects String, got Binary"),
        ({"sped": 1.0}, "has no channel 'sped'"),
    ],
)
def test_step_answers_are_checked(values_: dict[str, object], message: str) -> None:
    """Every way an answer is made refuses a wrong value naming its channel, also after a
    first answer prepared the message (the values then go into it in place)."""
    codec = wire.Codec(EVERY)
    answers = wire.StepAnswers(codec)
    answers.answer({k: OUTPUTS[k] for k in ("speed", "count", "on", "label")})
    for make in (lambda v: wire.step_response(v, codec), answers.answer):
        with pytest.raises(ChannelValueError, match=message):
            make(values_)
    with pytest.raises(ChannelValueError, match=message):  # in place: the same channels
        answers.answer({**{k: OUTPUTS[k] for k in ("speed", "count", "on", "label")}, **values_})


def test_decoding_refuses_what_check_refuses() -> None:
    """A binding's field fixes its Python type; a Real's finiteness, the channel, its field and
    the message's size are still checked, naming the channel."""
    codec = wire.Codec(EVERY, values.ValuePolicy(max_message_bytes=4))
    ok = [wire.pb.VariableBinding(channel="speed", real=1.5)]
    assert codec.decode(ok) == {"speed": 1.5}
    for binding, message in [
        (wire.pb.VariableBinding(channel="speed", real=math.inf), "expects a finite Real"),
        (wire.pb.VariableBinding(channel="speed", integer=1), "expects Real, got Integer"),
        (wire.pb.VariableBinding(channel="speed"), "expects Real, got no value"),
        (wire.pb.VariableBinding(channel="nope", real=1.0), "has no channel 'nope'"),
    ]:
        with pytest.raises(ChannelValueError, match=message):
            codec.decode([binding])
    allowed = values.ValuePolicy(allow_nonfinite=True)
    inf = wire.pb.VariableBinding(channel="speed", real=math.inf)
    assert wire.Codec(EVERY, allowed).decode([inf]) == {"speed": math.inf}
    with pytest.raises(MessageTooLarge, match="'label' carries 6 bytes"):
        codec.decode([wire.pb.VariableBinding(channel="label", text="äää")])
    assert codec.decode([wire.pb.VariableBinding(channel="label", text="ää")]) == {"label": "ää"}


FRAMES = Description(
    name="Camera",
    channels=(
        REAL,
        BIN,
        Channel(name="gain", causality=Causality.INPUT, type=ValueType.REAL),
        Channel(name="frame", causality=Causality.OUTPUT, type=ValueType.BINARY),
        Channel(name="depth", causality=Causality.OUTPUT, type=ValueType.BINARY),
        Channel(name="label", causality=Causality.OUTPUT, type=ValueType.STRING),
    ),
)
FRAME = bytes(range(256)) * (wire.LARGE_BYTES // 256 + 3)
"""A Binary value long enough to travel apart."""


def test_a_request_in_pieces_is_the_request() -> None:
    """``step_pieces``: the concatenation parses as ``step_to_pb``'s request, a long Binary
    input is one of the pieces itself (not copied), short ones stay in the message."""
    codec = wire.Codec(FRAMES)
    run = wire.RunKey("run-1", bytes(range(32)))
    for inputs in ({"blob": FRAME, "gain": 2.0}, {"blob": b"short", "gain": 2.0}, {"gain": 1.0}):
        pieces = wire.step_pieces(run, 1.5, 0.2, inputs, codec)
        parsed = wire.DoStepRequest.FromString(b"".join(pieces))
        expected = wire.step_to_pb(run, 1.5, 0.2, inputs, codec)
        assert codec.decode(parsed.inputs) == codec.decode(expected.inputs) == inputs
        assert (parsed.run_id, parsed.run_secret, parsed.current_time, parsed.step_size) == (
            expected.run_id,
            expected.run_secret,
            expected.current_time,
            expected.step_size,
        )
        assert any(p is FRAME for p in pieces) == (inputs.get("blob") is FRAME)


def test_a_request_in_pieces_is_checked() -> None:
    """Long values apart or not: a wrong channel or type, or a message over the limit, is
    refused naming the channel."""
    run = wire.RunKey("run-1", bytes(32))
    codec = wire.Codec(FRAMES)
    with pytest.raises(ChannelValueError, match="no input channel 'speed'"):
        wire.step_pieces(run, 0.0, 0.2, {"speed": FRAME}, codec)
    with pytest.raises(ChannelValueError, match="channel 'gain' expects Real, got Binary"):
        wire.step_pieces(run, 0.0, 0.2, {"gain": FRAME}, codec)
    small = wire.Codec(FRAMES, values.ValuePolicy(max_message_bytes=len(FRAME) - 1))
    with pytest.raises(MessageTooLarge, match=f"'blob' carries {len(FRAME)} bytes"):
        wire.step_pieces(run, 0.0, 0.2, {"blob": FRAME, "gain": 1.0}, small)


def test_an_answer_with_long_values_decodes_as_protobuf_decodes_it() -> None:
    """``step_answer`` cuts long Binary outputs out of the bytes; what it gives is what
    protobuf's own parsing gives, also for bindings it leaves to protobuf."""
    codec = wire.Codec(FRAMES)
    outputs = {"speed": 3.0, "frame": FRAME, "depth": FRAME[:100], "label": "ä"}
    response = wire.DoStepResponse(outputs=codec.encode(outputs))  # protobuf's own writing
    response.terminate, response.terminate_reason = True, "done"
    odd = response.outputs.add(channel="frame", binary=FRAME[::-1])  # the same channel again
    odd.real = 1.0  # oneof: now a Real, a binding step_answer leaves to protobuf
    parsed, large = wire.step_answer(response.SerializeToString())
    assert [name for name, _ in large] == ["frame"]
    assert wire.termination_requested(parsed) == "done"
    with pytest.raises(ChannelValueError, match="channel 'frame' expects Binary, got Real"):
        wire.outputs_from_pb(parsed, codec, large)
    del response.outputs[-1]
    data = response.SerializeToString()
    parsed, large = wire.step_answer(memoryview(data))
    assert wire.outputs_from_pb(parsed, codec, large) == outputs
    assert wire.outputs_from_pb(wire.DoStepResponse.FromString(data), codec) == outputs


def test_a_long_value_cut_out_of_an_answer_is_checked() -> None:
    """A long Binary answer for a channel that is not a Binary output, or over the limit, is
    refused as the same value parsed by protobuf would be; bytes that are not a message are
    left to protobuf, which says so."""
    response = wire.DoStepResponse()
    response.outputs.add(channel="speed", binary=FRAME)
    parsed, large = wire.step_answer(response.SerializeToString())
    assert large
    with pytest.raises(ChannelValueError, match="channel 'speed' expects Real, got Binary"):
        wire.outputs_from_pb(parsed, wire.Codec(FRAMES), large)
    response.outputs[0].channel = "blob"  # an input
    parsed, large = wire.step_answer(response.SerializeToString())
    with pytest.raises(ChannelValueError, match="no output channel 'blob'"):
        wire.outputs_from_pb(parsed, wire.Codec(FRAMES), large)
    response.outputs[0].channel = "frame"
    small = wire.Codec(FRAMES, values.ValuePolicy(max_message_bytes=len(FRAME) - 1))
    parsed, large = wire.step_answer(response.SerializeToString())
    with pytest.raises(MessageTooLarge, match=f"'frame' carries {len(FRAME)} bytes"):
        wire.outputs_from_pb(parsed, small, large)
    truncated = response.SerializeToString()[:-1]
    with pytest.raises(DecodeError):
        wire.step_answer(truncated)


def frame_of(pieces: list[bytes]) -> bytes | None:
    """The piece that is FRAME itself (the same object), if any."""
    return next((piece for piece in pieces if piece is FRAME), None)


def test_an_answer_writes_long_values_apart_and_protobuf_reads_it() -> None:
    """``step_response`` and ``StepAnswers`` write long Binary outputs after the message
    (bytes, not a message); protobuf parses those bytes into the same outputs as protobuf's
    own writing, ``step_answer`` cuts the long ones out again, and the end of a run survives."""
    codec = wire.Codec(FRAMES)
    outputs = {"speed": 3.0, "frame": FRAME, "depth": FRAME[::-1], "label": "ä"}
    pieces = wire.step_response(outputs, codec, terminate_reason="done")
    assert type(pieces) is wire.Pieces and frame_of(pieces) is not None  # not copied
    answer = wire.serialized(pieces)
    parsed = wire.DoStepResponse.FromString(answer)
    assert codec.decode(parsed.outputs) == outputs
    assert wire.termination_requested(parsed) == "done"
    cut, large = wire.step_answer(answer)
    assert sorted(name for name, _ in large) == ["depth", "frame"]
    assert wire.outputs_from_pb(cut, codec, large) == outputs
    short = {"speed": 1.0, "frame": b"short"}
    assert wire.serialized(wire.step_response(short, codec)) == (
        wire.DoStepResponse(outputs=codec.encode(short)).SerializeToString()
    )


def test_step_answers_with_long_values_carry_each_steps_outputs() -> None:
    """A stream's answers while a frame comes and goes, gets short and long again, or changes
    channel: each answer decodes to that step's outputs."""
    codec = wire.Codec(FRAMES)
    answers = wire.StepAnswers(codec)
    steps = [
        {"speed": 1.0, "frame": b"", "label": "a"},
        {"speed": 2.0, "frame": FRAME, "label": "b"},
        {"speed": 3.0, "frame": FRAME[::-1], "label": "c"},
        {"speed": 4.0, "frame": b"short", "label": "d"},
        {"speed": 5.0, "frame": FRAME, "label": "e"},
        {"speed": 6.0, "depth": FRAME, "label": "f"},
        {"speed": 7.0, "frame": bytearray(FRAME), "label": "g"},
        {"speed": 8.0, "frame": FRAME, "depth": FRAME[:10], "label": "h"},
        {"speed": 9.0, "frame": FRAME, "depth": FRAME, "label": "i"},
    ]
    for outputs in steps:
        answer = wire.serialized(answers.answer(outputs))
        parsed = wire.DoStepResponse.FromString(answer)
        assert codec.decode(parsed.outputs) == {k: bytes(v) if isinstance(v, bytearray) else v
                                                for k, v in outputs.items()}  # fmt: skip
    small = wire.StepAnswers(wire.Codec(FRAMES, values.ValuePolicy(max_message_bytes=100)))
    small.answer({"frame": FRAME[:50]})
    with pytest.raises(MessageTooLarge, match=f"'frame' carries {len(FRAME)} bytes"):
        small.answer({"frame": FRAME})


def test_step_answers_make_a_new_message_before_it_holds_too_much() -> None:
    """Text and bytes set into a reused message stay in its memory (protobuf's arena) until
    the message goes: after ``HELD_BYTES`` of them, the next answer is a message of its own."""
    codec = wire.Codec(FRAMES)
    answers = wire.StepAnswers(codec)
    first = answers.answer({"speed": 0.0, "label": ""})
    assert answers.answer({"speed": 1.0, "label": ""}) is first  # numbers only: in place
    text = "x" * 1000
    same = 0
    while answers.answer({"speed": 2.0, "label": text}) is first:
        same += 1
    assert 1 < same <= wire.HELD_BYTES // len(text)  # at most HELD_BYTES of text held
    again = answers.answer({"speed": 3.0, "label": "y"})
    assert codec.decode(again.outputs) == {"speed": 3.0, "label": "y"}  # type: ignore[union-attr]


def test_a_request_with_long_values_is_parsed_apart() -> None:
    """``step_request`` (the participant runtime's request parser) gives the inputs protobuf's
    parsing gives, its long Binary inputs cut out, from ``step_pieces``' bytes and from
    protobuf's own; a request that is not a message is protobuf's error."""
    codec = wire.Codec(FRAMES)
    run = wire.RunKey("run-1", bytes(range(32)))
    for inputs in ({"blob": FRAME, "gain": 2.0}, {"blob": b"short", "gain": 2.0}, {"gain": 1.0}):
        for data in (
            b"".join(wire.step_pieces(run, 1.5, 0.2, inputs, codec)),
            wire.step_to_pb(run, 1.5, 0.2, inputs, codec).SerializeToString(),
        ):
            request, large = wire.step_request(data)
            assert [name for name, _ in large] == (["blob"] if inputs.get("blob") is FRAME else [])
            step = wire.step_from_pb(request, codec, large)
            assert (step.run_id, step.time, step.step, step.inputs) == ("run-1", 1.5, 0.2, inputs)
    with pytest.raises(DecodeError):
        wire.step_request(b"".join(wire.step_pieces(run, 0.0, 0.2, {"blob": FRAME}, codec))[:-1])


# --- declared maxima (Channel.max_bytes) ---------------------------------------------------------

SIZED = Description(
    name="Camera",
    channels=(
        Channel(name="blob", causality=Causality.INPUT, type=ValueType.BINARY, max_bytes=10),
        Channel(name="label", causality=Causality.INPUT, type=ValueType.STRING, max_bytes=4),
        Channel(name="gain", causality=Causality.PARAMETER, type=ValueType.REAL),
        Channel(name="frame", causality=Causality.OUTPUT, type=ValueType.BINARY, max_bytes=20),
        Channel(name="speed", causality=Causality.OUTPUT, type=ValueType.REAL),
    ),
)


def test_a_value_over_its_declared_maximum_is_refused_both_ways() -> None:
    """Encoding and decoding, a message whole or in pieces, a prepared stream answer: a value
    over the maximum its channel declares names the channel, its size and the maximum; a
    String counts its UTF-8 bytes."""
    codec = wire.Codec(SIZED)
    assert codec.decode(codec.encode({"blob": bytes(10), "label": "abcd"}))
    with pytest.raises(ValueTooLarge) as info:
        codec.encode({"blob": bytes(11)})
    assert (info.value.channel, info.value.size, info.value.maximum) == ("blob", 11, 10)
    assert str(info.value).startswith(
        "input 'blob' carries 11 bytes, over its declared maximum of 10 bytes (max_bytes); send "
        "at most that"
    )
    assert info.value.naming("Camera").startswith("input Camera.blob carries 11 bytes")
    assert codec.encode({"label": "äbc"})  # 3 characters, 4 bytes: fits
    with pytest.raises(ValueTooLarge, match="input 'label' carries 5 bytes, over its declared"):
        codec.encode({"label": "äbcd"})
    undeclared = wire.Codec(
        replace(SIZED, channels=tuple(replace(c, max_bytes=0) for c in SIZED.channels))
    )
    with pytest.raises(ValueTooLarge, match="input 'blob' carries 11 bytes"):
        codec.decode(undeclared.encode({"blob": bytes(11)}))
    run = wire.RunKey("run-1", bytes(32))
    big = Description(
        name="Camera", channels=(replace(SIZED.channels[0], max_bytes=len(FRAME) - 1),)
    )
    with pytest.raises(ValueTooLarge, match=f"input 'blob' carries {len(FRAME)} bytes"):
        wire.step_pieces(run, 0.0, 0.1, {"blob": FRAME}, wire.Codec(big))
    answers = wire.StepAnswers(codec)
    answers.answer({"frame": bytes(20), "speed": 1.0})
    with pytest.raises(ValueTooLarge, match="output 'frame' carries 21 bytes") as info:
        answers.answer({"frame": bytes(21), "speed": 1.0})
    assert "the participant must send at most that, or declare a larger maximum" in str(info.value)


def test_declared_maxima_make_the_message_limit() -> None:
    """With every Binary and String channel of a message declared, its limit is their sum:
    above the policy's limit for a participant's own declarations, at most it where the
    policy caps them (the orchestrator's --max-message-size); one undeclared channel: the
    policy's limit."""
    policy = values.ValuePolicy(max_message_bytes=8)
    codec = wire.Codec(SIZED, policy)
    assert (codec.limit([Causality.INPUT]), codec.limit([Causality.OUTPUT])) == (14, 20)
    assert codec.decode(codec.encode({"blob": bytes(10), "label": "abcd"}))
    capped = wire.Codec(SIZED, replace(policy, cap_declared=True))
    assert (capped.limit([Causality.INPUT]), capped.limit([Causality.OUTPUT])) == (8, 8)
    with pytest.raises(MessageTooLarge, match="over the message limit of 8 bytes"):
        capped.encode({"blob": bytes(10)})
    mixed = replace(SIZED, channels=(*SIZED.channels, BIN))
    assert wire.Codec(mixed, policy).limit([Causality.INPUT]) == 8


def test_limits_of_servers_and_clients() -> None:
    """A participant's server receives parameters and inputs, sends outputs; its client the
    other way round, declared maxima capped by the run's limit, undeclared channels at least
    the default so an answer over the run's limit arrives and is named."""
    mib = 2**20
    assert wire.served_limits(SIZED, 64 * mib) == wire.MessageLimits(received=14, sent=20)
    assert wire.client_limits(SIZED, 64 * mib) == wire.MessageLimits(received=20, sent=14)
    assert wire.client_limits(SIZED, 16) == wire.MessageLimits(received=16, sent=14)
    assert wire.MessageLimits(received=20, sent=14).transport == (
        20 + wire.FRAMING_BYTES,
        14 + wire.FRAMING_BYTES,
    )
    undeclared = Description(name="P", channels=(REAL, BIN))  # and numbers only: the default
    assert wire.served_limits(undeclared, mib) == wire.MessageLimits(received=mib, sent=mib)
    assert wire.client_limits(undeclared, mib) == wire.MessageLimits()
    huge = Description(
        name="P",
        channels=(
            Channel(name="x", causality=Causality.INPUT, type=ValueType.BINARY, max_bytes=2**40),
        ),
    )
    assert wire.served_limits(huge, mib).transport[0] == 2**31 - 1


def test_step_answers_check_a_long_value_against_its_declared_maximum() -> None:
    """A long Binary output written apart is held to its channel's maximum on every answer,
    not only on the first (the prepared one)."""
    channels = tuple(
        replace(c, max_bytes=len(FRAME)) if c.name == "frame" else c for c in FRAMES.channels
    )
    answers = wire.StepAnswers(wire.Codec(replace(FRAMES, channels=channels)))
    answers.answer({"speed": 1.0, "frame": FRAME})
    answers.answer({"speed": 2.0, "frame": FRAME[::-1]})
    with pytest.raises(ValueTooLarge, match=f"{len(FRAME) + 1}"):
        answers.answer({"speed": 3.0, "frame": FRAME + b"x"})


def test_step_requests_hold_inputs_to_their_maxima_and_renew_their_message() -> None:
    """The prepared request checks every step's inputs against their declared maxima (not only
    the first step's), and is made anew once the Binary and String values set into it in place
    add up to ``HELD_BYTES`` (protobuf keeps each earlier value until the message goes)."""
    requests = wire.StepRequests(wire.Codec(SIZED), wire.RunKey("run-1", bytes(32)))
    first = requests.pieces(0.0, 0.1, {"blob": b"0123456789", "label": "abcd"})
    again = requests.pieces(0.1, 0.1, {"blob": b"9876543210", "label": "dcba"})
    parsed = wire.DoStepRequest.FromString(b"".join(again))
    assert (parsed.current_time, [b.binary or b.text for b in parsed.inputs]) == (
        0.1,
        [b"9876543210", "dcba"],
    )
    assert len(first) == len(again) == 1
    with pytest.raises(ValueTooLarge, match=r"'blob'.* 11 bytes"):
        requests.pieces(0.2, 0.1, {"blob": b"0123456789x", "label": "abcd"})
    big = Description(
        name="Sink",
        channels=(Channel(name="blob", causality=Causality.INPUT, type=ValueType.BINARY),),
    )
    requests = wire.StepRequests(wire.Codec(big), wire.RunKey("run-1", bytes(32)))
    value = bytes(wire.LARGE_BYTES - 1)  # set in place, not sent apart
    messages = set()
    for step in range(wire.HELD_BYTES // len(value) + 3):
        requests.pieces(step * 0.1, 0.1, {"blob": value})
        messages.add(id(requests._request))
    assert len(messages) == 2  # made anew once past HELD_BYTES
