"""A step's answer read in C (``coupler_native._answers``, csrc/answers.c, used by the native
step channel) gives exactly what protobuf and the codec give (``wire.step_answer``, then
``RemoteParticipant.step_outputs``' decoding), or None, and the caller reads it that way:

    answer bytes --AnswerRead.read--> (dict, step_seconds, waited_seconds)  (the plain form:
                 |                    outputs, each channel + value, and the step's cost only)
                 \\-> None --> step_answer --> Codec.decode --> dict, EndRun or the error

Every answer a participant's runtime writes (``wire.StepAnswers``) is in the plain form; any
message, and any bytes at all, give the same values both ways or None in C.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from coupler import values, wire
from coupler.channels import Causality, Channel, Description, ValueType
from coupler.costs import StepMeter
from coupler_orchestrator.master import native_step_channel

from ..support import require_native

OUTPUTS = {
    "speed": ValueType.REAL,
    "count": ValueType.INTEGER,
    "mode": ValueType.ENUMERATION,
    "on": ValueType.BOOLEAN,
    "label": ValueType.STRING,
    "data": ValueType.BINARY,
}
DESCRIPTION = Description(
    name="Every",
    channels=(
        Channel(name="u", causality=Causality.INPUT, type=ValueType.REAL),
        *(Channel(name=n, causality=Causality.OUTPUT, type=t) for n, t in OUTPUTS.items()),
    ),
)
FIELDS = ("real", "integer", "boolean", "text", "binary")
VALUES = {
    "real": st.floats(width=64),
    "integer": st.integers(-(2**31), 2**31 - 1),
    "boolean": st.booleans(),
    "text": st.text(max_size=6),
    "binary": st.binary(max_size=6) | st.just(bytes(wire.LARGE_BYTES + 3)),
}
NAMES = st.sampled_from([*OUTPUTS, "u", "nope", ""])


@st.composite
def bindings(draw: st.DrawFn) -> wire.pb.VariableBinding:
    """A binding of any channel name with any value (or none)."""
    binding = wire.pb.VariableBinding(channel=draw(NAMES))
    field = draw(st.sampled_from((*FIELDS, None)))
    if field is not None:
        setattr(binding, field, draw(VALUES[field]))
    return binding


def key(found: dict[str, Any]) -> list[tuple[str, type, Any]]:
    """Values compared by type and bits (nan equals nan, -0.0 is not 0.0), channel by channel
    in the channels' order (outputs are looked up by name: protobuf's path puts the long
    Binary values after the others, the C reader keeps the message's order)."""
    return [
        (n, type(v), struct.pack("<d", v) if isinstance(v, float) else v)
        for n, v in sorted(found.items(), key=lambda item: item[0])
    ]


def protobufs(data: bytes, codec: wire.Codec) -> tuple[dict[str, Any], float, float] | None:
    """What the native step channel makes of an answer without C: its outputs and the step's
    cost as reported, or None when it is refused or asks to end the run."""
    try:
        response, large = wire.step_answer(data)
        found = wire.outputs_from_pb(response, codec, large)
    except Exception:  # protobuf's DecodeError, the codec's refusals (CouplerError)
        return None
    if wire.termination_requested(response) is not None:
        return None
    return found, response.step_seconds, response.waited_seconds


def same(found: tuple[dict[str, Any], float, float], expected: Any) -> bool:
    """The same outputs (``key``) and the same cost figures, bit for bit."""
    assert expected is not None
    (outputs, *cost), (outputs_, *cost_) = found, expected
    return key(outputs) == key(outputs_) and struct.pack("<dd", *cost) == struct.pack("<dd", *cost_)


def reader(policy: values.ValuePolicy = values.DEFAULT_POLICY) -> tuple[Any, wire.Codec]:
    native = native_step_channel.answers()
    if native is None:
        require_native(native_step_channel.answers)
    codec = wire.Codec(DESCRIPTION, policy)
    return native.AnswerRead(codec.answer_fields(), policy.max_message_bytes).read, codec


POLICIES = st.sampled_from(
    [
        values.DEFAULT_POLICY,
        values.ValuePolicy(allow_nonfinite=True),
        values.ValuePolicy(max_message_bytes=8),
    ]
)


COSTS = st.sampled_from([0.0, 0.25, -1.0, math.nan]) | st.floats(width=64)


# long Binary values make examples whose repr hypothesis finds too large to print: its
# warning says nothing of the code under test
@pytest.mark.filterwarnings("ignore:Generating overly large repr")
@settings(max_examples=400, deadline=None)
@given(
    outputs=st.lists(bindings(), max_size=8),
    terminate=st.sampled_from([None, "", "enough"]),
    cost=st.tuples(COSTS, COSTS),
    policy=POLICIES,
)
def test_any_answer_is_read_as_protobuf_reads_it_or_left_to_it(
    outputs: list[wire.pb.VariableBinding],
    terminate: str | None,
    cost: tuple[float, float],
    policy: values.ValuePolicy,
) -> None:
    read, codec = reader(policy)
    response = wire.pb.DoStepResponse(outputs=outputs)
    response.step_seconds, response.waited_seconds = cost
    if terminate is not None:
        response.terminate, response.terminate_reason = True, terminate
    data = response.SerializeToString()
    found = read(memoryview(data))
    if found is not None:
        assert same(found, protobufs(data, codec)), (outputs, found)


@settings(max_examples=400, deadline=None)
@given(data=st.binary(max_size=60), policy=POLICIES)
def test_any_bytes_are_read_as_protobuf_reads_them_or_left_to_it(
    data: bytes, policy: values.ValuePolicy
) -> None:
    read, codec = reader(policy)
    found = read(data)
    if found is not None:
        assert same(found, protobufs(data, codec))


@given(
    speed=VALUES["real"].filter(math.isfinite),
    count=VALUES["integer"],
    mode=VALUES["integer"],
    on=st.booleans(),
    label=st.text(max_size=20),
    data=VALUES["binary"],
)
@example(speed=1.0, count=2, mode=3, on=True, label="x", data=bytes(range(256)) * 300)  # apart
def test_every_answer_a_participant_writes_is_read_in_c(**outputs: Any) -> None:
    """What the runtime answers (``StepAnswers``: the plain form, with the step's cost) is
    read in C, the values protobuf gives; a negative Integer (ten bytes on the wire) as well."""
    read, codec = reader()
    answers = wire.StepAnswers(codec)
    cost = StepMeter()
    for k, step in enumerate((outputs, {**outputs, "count": -1})):
        cost.seconds, cost.waited = 0.125 * (k + 1), 0.0625 * k  # as ``stop`` measures them
        data = wire.serialized(answers.answer(step, cost))  # long Binary values apart too
        found = read(memoryview(data))
        assert found is not None and found[1:] == (cost.seconds, cost.waited)
        assert same(found, protobufs(data, codec))


@pytest.mark.parametrize(
    ("response", "why"),
    [
        (wire.pb.DoStepResponse(terminate=True, terminate_reason="done"), "ends the run"),
        (wire.pb.DoStepResponse(outputs=[wire.pb.VariableBinding(channel="on")]), "no value"),
        (
            wire.pb.DoStepResponse(outputs=[wire.pb.VariableBinding(channel="on", real=1.0)]),
            "a Real for a Boolean",
        ),
        (
            wire.pb.DoStepResponse(
                outputs=[wire.pb.VariableBinding(channel="speed", real=-math.inf)]
            ),
            "not finite",
        ),
        (
            wire.pb.DoStepResponse(outputs=[wire.pb.VariableBinding(channel="u", real=1.0)]),
            "an input",
        ),
    ],
)
def test_what_is_not_a_plain_answer_is_left_to_protobuf(
    response: wire.pb.DoStepResponse, why: str
) -> None:
    read, _ = reader()
    assert read(response.SerializeToString()) is None, why
