from __future__ import annotations

import math

import pytest
from google.protobuf import source_context_pb2
from google.protobuf.message import DecodeError

from coupler import messages, values, wire
from coupler.channels import Causality, Channel, Description, ValueType, fits_fixed_step
from coupler.errors import ChannelValueError, MessageTooLarge

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
            ),
        ),
        implementation="test",
    )
    assert wire.description_from_pb(wire.description_to_pb(description)) == description


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
    response = wire.step_response(outputs, codec)
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
