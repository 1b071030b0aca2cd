"""The participant runtime and client against real gRPC servers on port 0.

RemoteParticipant --gRPC--> ParticipantServer(GainParticipant)
"""

from __future__ import annotations

import asyncio
import re
import secrets
from collections.abc import Mapping
from typing import TypeVar

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc

from coupler.channels import Description, RunSetup, Value
from coupler.client import RemoteParticipant, parse_address
from coupler.costs import waiting
from coupler.errors import ParticipantError, ParticipantUnavailable, ScenarioError
from coupler.examples.gain import GainParticipant
from coupler.participant import EndRun, HealthReport, Values
from coupler.server import ParticipantServer
from coupler.testing import eventually, served
from coupler.v1 import component_pb2 as pb
from coupler.v1 import component_pb2_grpc as pb_grpc

T = TypeVar("T")
KEY = secrets.token_bytes(32)
"""The run secret of raw requests."""


def setup(run_id: str = "t", lease: float = 0.0, **parameters: Value) -> RunSetup:
    return RunSetup(
        run_id=run_id, start_time=0.0, step_size=0.5, parameters=parameters, lease=lease
    )


async def test_every_value_type_round_trips(gain_server: ParticipantServer) -> None:
    async with RemoteParticipant(gain_server.address, streaming=False) as remote:
        initial = await remote.initialize(setup(gain=3.0, x0=1.0, offset=5))
        assert initial == {
            "y": 0.0,
            "x": 1.0,
            "count": 5,
            "inverted": True,
            "echo": "",
            "blob_out": b"",
        }
        inputs = {"u": 2.0, "n": -7, "flag": True, "label": "Zwönitz ✓", "blob": b"\x00\x01\xff"}
        out = await remote.do_step(0.0, 0.5, inputs)
        assert out["y"] == 6.0
        assert out["x"] == 2.0
        assert out["count"] == -2
        assert out["inverted"] is False
        assert out["echo"] == "Zwönitz ✓"
        assert out["blob_out"] == b"\xff\x01\x00"
        await remote.terminate()


async def test_streaming_gives_the_same_outputs_as_unary(gain_server: ParticipantServer) -> None:
    steps = [{"u": float(k), "n": k, "flag": k % 2 == 0, "label": f"s{k}"} for k in range(20)]
    traces = []
    for streaming in (False, True):
        async with RemoteParticipant(gain_server.address, streaming=streaming) as remote:
            trace = [await remote.initialize(setup())]
            for k, inputs in enumerate(steps):
                trace.append(await remote.do_step(k * 0.5, 0.5, inputs))
            await remote.terminate()
            traces.append(trace)
    assert traces[0] == traces[1]
    assert traces[0][-1]["x"] == sum(range(20)) * 0.5


async def test_long_binary_values_cross_as_protobuf_writes_them(
    gain_server: ParticipantServer,
) -> None:
    """Camera-sized Binary values (``wire.LARGE_BYTES`` and more) are cut out of a request's
    bytes and written after an answer's message by the runtime (``wire.step_request``,
    ``wire.step_response``): the Coupler client on both step paths and a client with
    protobuf's own generated code see the same values, long and short by turns."""
    frames = [bytes([k]) * 3 + bytes(range(256)) * 5625 for k in range(3)]  # 1.44 MB each
    blobs = [frames[0], b"short", frames[1], b"", frames[2]]
    for streaming in (False, True):
        async with RemoteParticipant(gain_server.address, streaming=streaming) as remote:
            await remote.initialize(setup())
            for k, blob in enumerate(blobs):
                out = await remote.do_step(k * 0.5, 0.5, {"u": float(k), "blob": blob})
                assert out["blob_out"] == blob[::-1]
            await remote.terminate()
    channel, stub = await raw_stub(gain_server.address)
    async with channel:
        await stub.Initialize(pb.InitializeRequest(run_id="raw", run_secret=KEY, step_size=0.5))
        stream = stub.StepStream()
        for k, blob in enumerate(blobs):
            binding = pb.VariableBinding(channel="blob", binary=blob)
            await stream.write(
                pb.DoStepRequest(
                    run_id="raw", run_secret=KEY, current_time=k * 0.5, step_size=0.5,
                    inputs=[binding],
                )
            )  # fmt: skip
            answer = await stream.read()
            assert {b.channel: b.WhichOneof("value") for b in answer.outputs}["blob_out"] == (
                "binary"
            )
            assert [b.binary for b in answer.outputs if b.channel == "blob_out"] == [blob[::-1]]
        await stream.done_writing()
        await stub.Terminate(pb.TerminateRequest(run_id="raw", run_secret=KEY))


async def test_step_before_initialize_is_failed_precondition(
    gain_server: ParticipantServer,
) -> None:
    async with RemoteParticipant(gain_server.address) as remote:
        with pytest.raises(ParticipantError, match="DoStep before Initialize") as info:
            await remote.do_step(0.0, 0.5, {})
    assert info.value.status == "FAILED_PRECONDITION"


async def test_second_concurrent_run_is_refused(gain_server: ParticipantServer) -> None:
    async with (
        RemoteParticipant(gain_server.address) as first,
        RemoteParticipant(gain_server.address) as second,
    ):
        await first.initialize(setup())
        with pytest.raises(
            ParticipantError, match=r"is in another run .*one run at a time"
        ) as info:
            await second.initialize(setup("other"))
        assert info.value.status == "FAILED_PRECONDITION"
        assert "'t'" not in str(info.value)  # the active run's id is its capability
        await first.terminate()
        await second.initialize(setup())  # free again after Terminate
        await second.terminate()


@pytest.mark.parametrize(
    ("binding", "message"),
    [
        (
            pb.VariableBinding(channel="nope", real=1.0),
            "has no channel 'nope' (input channels: blob, flag",
        ),
        (pb.VariableBinding(channel="u", text="fast"), "channel 'u' expects Real, got String"),
        (pb.VariableBinding(channel="n", real=1.5), "channel 'n' expects Integer, got Real"),
        (pb.VariableBinding(channel="y", real=1.0), "has no input channel 'y'"),
    ],
)
async def test_wrong_channel_or_type_is_invalid_argument(
    gain_server: ParticipantServer, binding: pb.VariableBinding, message: str
) -> None:
    # the raw stub: the client would refuse these before sending
    async with grpc.aio.insecure_channel(parse_address(gain_server.address)) as channel:
        stub = pb_grpc.GRPCComponentServiceStub(channel)
        await stub.Initialize(pb.InitializeRequest(run_id="raw", run_secret=KEY, step_size=0.5))
        with pytest.raises(grpc.aio.AioRpcError) as info:
            await stub.DoStep(
                pb.DoStepRequest(
                    run_id="raw", run_secret=KEY, current_time=0, step_size=0.5, inputs=[binding]
                )
            )
        assert info.value.code() is grpc.StatusCode.INVALID_ARGUMENT
        assert message in (info.value.details() or "")
        await stub.Terminate(pb.TerminateRequest(run_id="raw", run_secret=KEY))


class Faulty(GainParticipant):
    """Raises inside do_step when asked to."""

    async def do_step(
        self, time: float, step: float, inputs: Mapping[str, Value]
    ) -> dict[str, Value]:
        if inputs.get("label") == "explode":
            raise ZeroDivisionError("the model divided by zero at the viaduct")
        return await super().do_step(time, step, inputs)


async def test_participant_exception_is_internal_and_server_keeps_serving() -> None:
    async with served(Faulty()) as server:
        async with RemoteParticipant(server.address, streaming=False) as remote:
            await remote.initialize(setup())
            with pytest.raises(
                ParticipantError, match="ZeroDivisionError: the model divided"
            ) as info:
                await remote.do_step(0.0, 0.5, {"label": "explode"})
            assert info.value.status == "INTERNAL"
            assert (await remote.do_step(0.5, 0.5, {"u": 1.0}))["x"] == 0.5  # same run goes on
            await remote.terminate()
        async with RemoteParticipant(server.address) as remote:  # streaming
            await remote.initialize(setup())
            with pytest.raises(ParticipantError, match="ZeroDivisionError") as info:
                await remote.do_step(0.0, 0.5, {"label": "explode"})
            assert info.value.status == "INTERNAL"
        # the failed stream ended its run: the participant serves the next one
        async with RemoteParticipant(server.address) as remote:
            await eventually(lambda: remote.initialize(setup("next")), retry=ParticipantError)
            assert (await remote.do_step(0.0, 0.5, {"u": 1.0}))["x"] == 0.5
            await remote.terminate()


class Varying(GainParticipant):
    """Answers with fewer outputs when ``n`` is 1 and a wrong type when ``n`` is 2."""

    async def do_step(
        self, time: float, step: float, inputs: Mapping[str, Value]
    ) -> dict[str, Value]:
        outputs = await super().do_step(time, step, inputs)
        if inputs.get("n") == 1:
            return {"y": outputs["y"]}
        if inputs.get("n") == 2:
            return {**outputs, "count": "three"}  # type: ignore[dict-item]
        return outputs


async def test_a_step_stream_answers_every_step_with_its_own_outputs() -> None:
    """A stream's answers share one prepared message (coupler.wire.StepAnswers): each answer
    still carries that step's outputs, when they change channels too, and each is checked."""
    server = ParticipantServer(Varying())
    await server.start()
    try:
        async with RemoteParticipant(server.address) as remote:  # streaming
            await remote.initialize(setup())
            first = await remote.do_step(0.0, 0.5, {"u": 1.0, "label": "a", "blob": b"ab"})
            assert first == {"y": 2.0, "x": 0.5, "count": 0, "inverted": True, "echo": "a",
                             "blob_out": b"ba"}  # fmt: skip
            assert await remote.do_step(0.5, 0.5, {"u": 2.0, "n": 1}) == {"y": 4.0}
            later = await remote.do_step(1.0, 0.5, {"u": 3.0, "n": 0, "label": "", "blob": b""})
            assert later == {"y": 6.0, "x": 3.0, "count": 0, "inverted": True, "echo": "",
                             "blob_out": b""}  # fmt: skip
            again = await remote.do_step(1.5, 0.5, {"u": -1.0, "flag": True, "n": 5})
            assert (again["y"], again["x"], again["count"], again["inverted"]) == (
                -2.0, 2.5, 5, False
            )  # fmt: skip
            with pytest.raises(
                ParticipantError, match="channel 'count' expects Integer, got String"
            ) as info:
                await remote.do_step(2.0, 0.5, {"n": 2})
            assert info.value.status == "INVALID_ARGUMENT"
    finally:
        await server.stop(grace=0.1)


class SlowToOpen(GainParticipant):
    def __init__(self) -> None:
        super().__init__()
        self.release = asyncio.Event()
        self.opening = asyncio.Event()

    async def open(self) -> None:
        self.opening.set()
        await self.release.wait()


async def health_of(address: str) -> int:
    async with grpc.aio.insecure_channel(parse_address(address)) as channel:
        reply = await health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest())
        return int(reply.status)


async def test_health_follows_the_participant() -> None:
    participant = SlowToOpen()
    server = ParticipantServer(participant)
    starting = asyncio.create_task(server.start())
    await participant.opening.wait()  # bound and serving health, participant not open yet
    assert await health_of(server.address) == health_pb2.HealthCheckResponse.NOT_SERVING
    participant.release.set()
    await starting
    assert await health_of(server.address) == health_pb2.HealthCheckResponse.SERVING

    async with grpc.aio.insecure_channel(parse_address(server.address)) as channel:
        watch = health_pb2_grpc.HealthStub(channel).Watch(health_pb2.HealthCheckRequest())
        seen = [(await watch.read()).status]
        stopping = asyncio.create_task(server.stop(grace=0.5))
        seen.append((await watch.read()).status)
        await stopping
    assert seen == [
        health_pb2.HealthCheckResponse.SERVING,
        health_pb2.HealthCheckResponse.NOT_SERVING,
    ]


class WrapsASimulator(GainParticipant):
    """Says through ``watch_health`` whether its (imagined) simulator is up."""

    async def watch_health(self, report: HealthReport) -> None:
        self.report = report
        await report("simulator at http://sim:1 is down")


async def test_health_carries_the_participants_reason() -> None:
    participant = WrapsASimulator()
    async with served(participant) as server:
        # NOT_SERVING throughout: open fails at the deadline saying why (room to connect)
        remote = RemoteParticipant(server.address, connect_timeout=1.5)
        with pytest.raises(ParticipantUnavailable) as waiting:
            await remote.open()
        with pytest.raises(ParticipantUnavailable) as probed:
            await remote.wait_until_serving_once()
        await remote.close()
        await participant.report(None)
        async with RemoteParticipant(server.address, connect_timeout=2.0) as remote:
            assert (await remote.initialize(setup(gain=2.0)))["y"] == 0.0
    reason = "health is NOT_SERVING: simulator at http://sim:1 is down"
    assert reason in str(waiting.value) and reason in str(probed.value)


async def test_unreachable_participant_is_unavailable_within_deadline() -> None:
    remote = RemoteParticipant("grpc://127.0.0.1:9", connect_timeout=0.5)
    with pytest.raises(
        ParticipantUnavailable, match=r"not SERVING at grpc://127.0.0.1:9 within 0.5 s"
    ):
        await remote.open()
    await remote.close()


@pytest.mark.parametrize(
    "address",
    [
        "http://example:80",
        "grpc://127.0.0.1:1/../x",  # a path: accepted, and silently dropped, before
        "grpc://127.0.0.1:1/x",
        "grpc://127.0.0.1:1?x=1",
        "grpc://127.0.0.1:1#x",
        "grpc://user@127.0.0.1:1",
    ],
)
def test_bad_address_says_how_to_write_one(address: str) -> None:
    with pytest.raises(ScenarioError, match="write grpc://HOST:PORT"):
        parse_address(address)


@pytest.mark.parametrize("address", ["unix://relative", "unix:///tmp/x?y", "unix:///tmp/x#y"])
def test_bad_unix_address_says_how_to_write_one(address: str) -> None:
    with pytest.raises(ScenarioError, match="write unix:///ABSOLUTE/PATH"):
        parse_address(address)


async def test_describe_over_the_wire_equals_local(gain_server: ParticipantServer) -> None:
    async with RemoteParticipant(gain_server.address) as remote:
        remote_description: Description = await remote.describe()
    assert remote_description == await GainParticipant().describe()


async def raw_stub(address: str) -> tuple[grpc.aio.Channel, pb_grpc.GRPCComponentServiceStub]:
    channel = grpc.aio.insecure_channel(parse_address(address))
    return channel, pb_grpc.GRPCComponentServiceStub(channel)


async def test_calls_of_another_run_are_refused(gain_server: ParticipantServer) -> None:
    """A second client cannot step or end a run it did not start (run leases).

    orchestrator --Initialize(run A), DoStep(A)--> Gain <--DoStep(B), Terminate(B)-- intruder
    """
    async with RemoteParticipant(gain_server.address, streaming=False) as owner:
        await owner.initialize(setup("A"))
        channel, intruder = await raw_stub(gain_server.address)
        async with channel:
            bad = pb.VariableBinding(channel="u", real=5e9)
            for call in (
                intruder.DoStep(pb.DoStepRequest(run_id="B", step_size=0.5, inputs=[bad])),
                intruder.DoStep(pb.DoStepRequest(step_size=0.5, inputs=[bad])),
                intruder.Terminate(pb.TerminateRequest(run_id="B")),
            ):
                with pytest.raises(grpc.aio.AioRpcError) as info:
                    await call
                assert info.value.code() is grpc.StatusCode.FAILED_PRECONDITION
                assert "not participant 'Gain's active run" in (info.value.details() or "")
        out = await owner.do_step(0.0, 0.5, {"u": 1.0})
        assert (out["y"], out["x"]) == (2.0, 0.5)  # nothing injected
        await owner.terminate()
        await owner.terminate()  # Terminate of an ended run is answered OK


async def test_a_silent_run_ends_when_its_lease_expires(gain_server: ParticipantServer) -> None:
    """An orchestrator that dies (no more calls) does not lock the participant."""
    async with RemoteParticipant(gain_server.address, streaming=False) as dead:
        await dead.initialize(setup("dead", lease=0.3))
        async with RemoteParticipant(gain_server.address) as next_one:
            await eventually(lambda: next_one.initialize(setup("next")), retry=ParticipantError)
            assert (await next_one.do_step(0.0, 0.5, {"u": 2.0}))["y"] == 4.0
            await next_one.terminate()
        with pytest.raises(ParticipantError, match="DoStep before Initialize") as info:
            await dead.do_step(0.0, 0.5, {})
        assert info.value.status == "FAILED_PRECONDITION"


async def test_a_run_ends_with_its_broken_step_stream(gain_server: ParticipantServer) -> None:
    """The stream that carried a run ends (the orchestrator's process is gone): so does the run,
    long before its lease."""
    lost = RemoteParticipant(gain_server.address)
    await lost.open()
    await lost.initialize(setup("lost", lease=600))
    await lost.do_step(0.0, 0.5, {"u": 1.0})
    await lost.close()  # cancels the stream, no Terminate
    async with RemoteParticipant(gain_server.address) as next_one:
        await eventually(
            lambda: next_one.initialize(setup("next")), within=3.0, retry=ParticipantError
        )
        await next_one.terminate()


class Emptying(GainParticipant):
    """Asks to end the run once x reaches 1 (a tank running dry)."""

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        outputs = await super().do_step(time, step, inputs)
        if float(outputs["x"]) >= 1.0:
            raise EndRun(f"tank empty at t={time + step:g}", outputs)
        return outputs


@pytest.mark.parametrize("streaming", [False, True])
async def test_a_participant_may_end_the_run(streaming: bool) -> None:
    async with (
        served(Emptying()) as server,
        RemoteParticipant(server.address, streaming=streaming) as remote,
    ):
        await remote.initialize(setup())
        assert (await remote.do_step(0.0, 0.5, {"u": 1.0}))["x"] == 0.5
        with pytest.raises(EndRun, match="tank empty at t=1") as info:
            await remote.do_step(0.5, 0.5, {"u": 1.0})
        assert info.value.outputs["x"] == 1.0
        await remote.terminate("participant asked")


@pytest.mark.parametrize(
    ("lease", "shown"),
    [(float("inf"), "inf"), (float("nan"), "nan"), (-1.0, "-1.0"), (86_400.5, "86400.5")],
)
async def test_a_lease_without_a_ceiling_is_refused(
    gain_server: ParticipantServer, lease: float, shown: str
) -> None:
    """Initialize(lease_seconds=inf) once locked a participant for good: a lease is a finite
    number of seconds up to 24 h, else INVALID_ARGUMENT naming the value and the bound, and
    the participant stays free."""
    channel, stub = await raw_stub(gain_server.address)
    async with channel:
        with pytest.raises(grpc.aio.AioRpcError) as info:
            await stub.Initialize(
                pb.InitializeRequest(run_id="x", run_secret=KEY, step_size=0.5, lease_seconds=lease)
            )
        assert info.value.code() is grpc.StatusCode.INVALID_ARGUMENT
        assert (
            f"lease_seconds must be a number of seconds > 0 and <= 86400 (24 h), got {shown}"
            in (info.value.details() or "")
        )
    async with RemoteParticipant(gain_server.address) as next_one:
        await next_one.initialize(
            setup("next", lease=86_400)
        )  # free, and the ceiling itself is fine
        await next_one.terminate()


@pytest.mark.parametrize(
    ("request_fields", "message"),
    [
        ({"current_time": 0.0, "step_size": float("inf")}, "step_size=inf"),
        ({"current_time": float("nan"), "step_size": 0.5}, "current_time=nan"),
    ],
)
async def test_a_step_of_infinite_or_nan_time_is_refused(
    gain_server: ParticipantServer, request_fields: dict[str, float], message: str
) -> None:
    async with RemoteParticipant(gain_server.address, streaming=False) as owner:
        await owner.initialize(setup("A"))
        with pytest.raises(ParticipantError, match=f"must be finite.*{message}") as info:
            await owner.do_step(request_fields["current_time"], request_fields["step_size"], {})
        assert info.value.status == "INVALID_ARGUMENT"
        await owner.terminate()


async def test_initialize_without_a_run_secret_is_refused(gain_server: ParticipantServer) -> None:
    channel, stub = await raw_stub(gain_server.address)
    async with channel:
        for secret in (b"", b"short", bytes(257)):
            with pytest.raises(grpc.aio.AioRpcError) as info:
                await stub.Initialize(
                    pb.InitializeRequest(run_id="x", run_secret=secret, step_size=0.5)
                )
            assert info.value.code() is grpc.StatusCode.INVALID_ARGUMENT
            assert f"run_secret must be 16 to 256 random bytes, got {len(secret)}" in (
                info.value.details() or ""
            )


@pytest.mark.parametrize("streaming", [False, True])
async def test_calls_of_the_run_without_its_secret_are_refused_and_fail_the_run(
    gain_server: ParticipantServer, streaming: bool
) -> None:
    """Whoever knows the run id but not the run's secret changes nothing, ends nothing, and
    the run's owner is told at its next call (ABORTED), which names the intrusion.

    owner --Initialize(A, secret), DoStep--> Gain <--DoStep/StepStream/Terminate(A)-- stranger
    """
    async with RemoteParticipant(gain_server.address, streaming=streaming) as owner:
        await owner.initialize(setup("A", gain=2.0))
        assert (await owner.do_step(0.0, 0.5, {"u": 1.0}))["y"] == 2.0
        channel, stranger = await raw_stub(gain_server.address)
        async with channel:
            huge = [pb.VariableBinding(channel="u", real=1e300)]
            stream = stranger.StepStream()
            await stream.write(pb.DoStepRequest(run_id="A", step_size=0.5, inputs=huge))
            await stream.done_writing()
            for call in (
                stranger.DoStep(pb.DoStepRequest(run_id="A", step_size=0.5, inputs=huge)),
                stranger.DoStep(
                    pb.DoStepRequest(run_id="A", run_secret=KEY, step_size=0.5, inputs=huge)
                ),
                stranger.Terminate(pb.TerminateRequest(run_id="A")),
            ):
                with pytest.raises(grpc.aio.AioRpcError) as info:
                    await call
                assert info.value.code() is grpc.StatusCode.PERMISSION_DENIED
                assert "names participant 'Gain's active run but does not carry that run's " in (
                    info.value.details() or ""
                )
            assert await stream.code() is grpc.StatusCode.PERMISSION_DENIED
        with pytest.raises(ParticipantError) as refused:
            await owner.do_step(0.5, 0.5, {"u": 1.0})
        assert refused.value.status == "ABORTED"
        assert re.fullmatch(
            r"Gain refused the run: a call without this run's secret arrived from "
            r"ipv4:127\.0\.0\.1:\d+ \(DoStep at t=0\.5 s\); the run is no "
            r"longer trusted \(3 more such calls since\)",
            refused.value.detail,
        ), refused.value.detail
        if not streaming:  # (a refused stream ends the run with it, as every broken stream)
            with pytest.raises(ParticipantError, match="Gain refused the run") as told:
                await owner.terminate()
            assert told.value.status == "ABORTED"
        else:
            await owner.terminate()
    async with RemoteParticipant(gain_server.address) as next_one:  # the participant is free
        await eventually(lambda: next_one.initialize(setup("next")), retry=ParticipantError)
        await next_one.terminate()


class Waiting(GainParticipant):
    """Takes ``own`` seconds of its own per step and waits ``outside`` seconds for an outside
    program (``waiting()``)."""

    def __init__(self, own: float, outside: float) -> None:
        super().__init__()
        self.own, self.outside = own, outside

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        await asyncio.sleep(self.own)
        with waiting():
            await asyncio.sleep(self.outside)
        if time >= 1.0:
            raise EndRun("enough", await super().do_step(time, step, inputs))
        return await super().do_step(time, step, inputs)


@pytest.mark.parametrize("streaming", [False, True])
async def test_every_answer_says_what_its_step_cost_and_what_it_waited(streaming: bool) -> None:
    """The runtime measures each step around the participant's ``do_step`` and sends the
    figure with the outputs (``DoStepResponse.step_seconds``; the part marked with
    ``waiting()``: ``waited_seconds``), over DoStep and StepStream, on an answer that ends the
    run too; the client keeps what the last one said (``RemoteParticipant.reported``)."""
    server = ParticipantServer(Waiting(own=0.03, outside=0.04))
    await server.start()
    try:
        async with RemoteParticipant(server.address, streaming=streaming) as remote:
            await remote.initialize(setup())
            assert remote.reported == (None, None)
            for time in (0.0, 0.5, 1.0):
                try:
                    await remote.do_step(time, 0.5, {"u": 1.0})
                except EndRun:
                    assert time == 1.0
                seconds, waited = remote.reported
                assert seconds is not None and waited is not None
                assert 0.04 <= waited < seconds and seconds >= 0.07, remote.reported
            await remote.terminate()
    finally:
        await server.stop(grace=0.1)
