"""Declared maxima (``Channel.max_bytes``) against real gRPC servers on loopback.

    RemoteParticipant --frame (Binary, <= 2 MB)--> ParticipantServer(Echo) --echo (<= 2 MB)-->

A 1.44 MB frame (800 x 600 x 3) passes both ways with the limits derived from the
declarations: the participant's server takes more than its default (1 MiB here) because its
input declares 2 MB, the client's channel less than its 64 MiB default because the outputs
declare 2 MB. A value over its channel's maximum is refused naming the channel, its size and
the maximum: by the participant that would send it, by the client that would send it, and by
the client that receives it from a participant breaking its own declaration.
"""

from __future__ import annotations

import re
import secrets
from collections.abc import AsyncIterator, Mapping
from pathlib import Path

import grpc
import pytest
from grpc_health.v1 import health, health_pb2, health_pb2_grpc

from coupler import ports, wire
from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError
from coupler.participant import Participant, Values
from coupler.security import ClientSecurity, ServerSecurity
from coupler.server import ParticipantServer
from coupler.testing import served
from coupler.v1 import component_pb2 as pb
from coupler.v1 import component_pb2_grpc as pb_grpc
from coupler_dev.devcerts import write_pki

FRAME = 800 * 600 * 3
MAXIMUM = 2_000_000
MIB = 2**20


class Echo(Participant):
    """Input ``frame`` and output ``echo``, Binary, at most ``MAXIMUM`` bytes each; the echo
    is the frame and ``extra`` bytes more (to break the declaration)."""

    def __init__(self, extra: int = 0) -> None:
        self.extra = extra

    async def describe(self) -> Description:
        return Description(
            name="Echo",
            channels=(
                Channel(
                    name="frame", causality=Causality.INPUT, type=ValueType.BINARY, start=b"",
                    max_bytes=MAXIMUM,
                ),
                Channel(
                    name="echo", causality=Causality.OUTPUT, type=ValueType.BINARY,
                    max_bytes=MAXIMUM,
                ),
                Channel(name="size", causality=Causality.OUTPUT, type=ValueType.INTEGER),
            ),
        )  # fmt: skip

    async def initialize(self, setup: RunSetup) -> Values:
        return {"echo": b"", "size": 0}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        frame = bytes(inputs.get("frame", b""))
        echo = frame + bytes(self.extra) if frame else b""
        return {"echo": echo, "size": len(frame)}

    async def terminate(self, reason: str = "") -> None:
        return None


def setup() -> RunSetup:
    return RunSetup(run_id="sizes", start_time=0.0, step_size=0.1)


@pytest.mark.parametrize("streaming", [True, False])
async def test_a_frame_passes_with_limits_from_the_declarations(streaming: bool) -> None:
    async with served(Echo(), max_message_bytes=MIB) as server:
        assert server.limits == wire.MessageLimits(received=MAXIMUM, sent=MAXIMUM)
        async with RemoteParticipant(server.address, streaming=streaming) as remote:
            assert remote.limits == wire.MessageLimits(received=MAXIMUM, sent=MAXIMUM)
            await remote.initialize(setup())
            frame = secrets.token_bytes(FRAME)
            for k in range(3):
                outputs = await remote.do_step(k * 0.1, 0.1, {"frame": frame})
                assert outputs == {"echo": frame, "size": FRAME}
            await remote.terminate()


async def test_the_servers_transport_follows_the_declarations() -> None:
    """A message far over the declared input (more than the framing past it) meets gRPC's
    own refusal, at the declared maximum plus framing: the server was bound again with it."""
    async with served(Echo()) as server:
        options = wire.MessageLimits(received=64 * MIB, sent=64 * MIB).options()
        target = server.address.removeprefix("grpc://")
        async with grpc.aio.insecure_channel(target, options=options) as channel:
            stub = pb_grpc.GRPCComponentServiceStub(channel)
            huge = pb.VariableBinding(channel="frame", binary=bytes(MAXIMUM + wire.FRAMING_BYTES))
            request = pb.InitializeRequest(
                run_id="raw", run_secret=bytes(32), step_size=0.1, inputs=[huge]
            )
            with pytest.raises(grpc.aio.AioRpcError) as info:
                await stub.Initialize(request)
    assert info.value.code() is grpc.StatusCode.RESOURCE_EXHAUSTED
    limit = re.search(r"vs\. (\d+)\)", info.value.details() or "")
    assert limit is not None, info.value.details()
    assert int(limit.group(1)) == MAXIMUM + wire.FRAMING_BYTES


async def test_a_participant_refuses_to_send_more_than_it_declares() -> None:
    async with (
        served(Echo(extra=1)) as server,
        RemoteParticipant(server.address, name="Echo") as remote,
    ):
        await remote.initialize(setup())
        with pytest.raises(ParticipantError) as info:
            await remote.do_step(0.0, 0.1, {"frame": bytes(MAXIMUM)})
        await remote.terminate()
    assert info.value.status == "RESOURCE_EXHAUSTED"
    assert str(info.value).startswith(
        f"Echo.DoStep [RESOURCE_EXHAUSTED]: output 'echo' carries {MAXIMUM + 1} bytes, over its "
        f"declared maximum of {MAXIMUM} bytes (max_bytes); the participant must send at most "
        f"that, or declare a larger maximum"
    )


async def test_an_input_over_its_declared_maximum_is_refused_before_it_is_sent() -> None:
    async with (
        served(Echo()) as server,
        RemoteParticipant(server.address, name="Echo") as remote,
    ):
        await remote.initialize(setup())
        with pytest.raises(ParticipantError) as info:
            await remote.do_step(0.0, 0.1, {"frame": bytes(MAXIMUM + 1)})
        assert (await remote.do_step(0.0, 0.1, {"frame": b"ok"}))["size"] == 2
        await remote.terminate()
    assert info.value.status == "RESOURCE_EXHAUSTED"
    assert str(info.value).startswith(
        f"Echo.DoStep [RESOURCE_EXHAUSTED]: input Echo.frame carries {MAXIMUM + 1} bytes, over "
        f"its declared maximum of {MAXIMUM} bytes"
    )


class Liar(pb_grpc.GRPCComponentServiceServicer):
    """A participant not built on Coupler's runtime that answers more than it declares."""

    async def Describe(self, request: pb.DescribeRequest, context: object) -> pb.DescribeResponse:
        frame = pb.ChannelDescription(
            name="frame",
            causality=pb.CAUSALITY_OUTPUT,
            type=pb.VALUE_TYPE_BINARY,
            max_bytes=10,
        )
        return pb.DescribeResponse(name="Liar", channels=[frame])

    async def Initialize(
        self, request: pb.InitializeRequest, context: object
    ) -> pb.InitializeResponse:
        return pb.InitializeResponse(
            outputs=[pb.VariableBinding(channel="frame", binary=bytes(11))]
        )

    async def Terminate(
        self, request: pb.TerminateRequest, context: object
    ) -> pb.TerminateResponse:
        return pb.TerminateResponse()


@pytest.fixture
async def liar() -> AsyncIterator[str]:
    server = grpc.aio.server(options=ports.GRPC_SERVER_OPTIONS)
    pb_grpc.add_GRPCComponentServiceServicer_to_server(Liar(), server)
    checks = health.aio.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(checks, server)
    port = server.add_insecure_port("127.0.0.1:0")
    await server.start()
    await checks.set("", health_pb2.HealthCheckResponse.SERVING)
    yield f"grpc://127.0.0.1:{port}"
    await server.stop(0)


async def test_an_answer_over_its_declared_maximum_is_refused(liar: str) -> None:
    async with RemoteParticipant(liar, name="Liar") as remote:
        with pytest.raises(ParticipantError) as info:
            await remote.initialize(setup())
        await remote.terminate()
    assert str(info.value).startswith(
        "Liar.Initialize [RESOURCE_EXHAUSTED]: output Liar.frame carries 11 bytes, over its "
        "declared maximum of 10 bytes (max_bytes)"
    )


async def test_an_undeclared_participant_keeps_the_default_limits() -> None:
    class Undeclared(Echo):
        async def describe(self) -> Description:
            described = await super().describe()
            channels = tuple(
                Channel(name=c.name, causality=c.causality, type=c.type, start=c.start)
                for c in described.channels
            )
            return Description(name="Undeclared", channels=channels)

    server = ParticipantServer(Undeclared(), max_message_bytes=MIB)
    await server.start()
    try:
        assert server.limits == wire.MessageLimits(received=MIB, sent=MIB)
        async with RemoteParticipant(server.address) as remote:
            assert remote.limits == wire.MessageLimits()  # 64 MiB either way, as before
            await remote.initialize(setup())
            with pytest.raises(ParticipantError, match="over the message limit of 1048576"):
                await remote.do_step(0.0, 0.1, {"frame": bytes(FRAME)})
            await remote.terminate()
    finally:
        await server.stop(grace=0.1)


async def test_a_server_on_a_unix_socket_is_bound_again_there(tmp_path: Path) -> None:
    async with served(Echo(), unix_socket=tmp_path / "echo.sock") as server:
        assert server.address == f"unix://{tmp_path / 'echo.sock'}"
        async with RemoteParticipant(server.address) as remote:
            await remote.initialize(setup())
            assert (await remote.do_step(0.0, 0.1, {"frame": bytes(FRAME)}))["size"] == FRAME
            await remote.terminate()


async def test_a_server_with_mutual_tls_and_a_token_is_bound_again_with_them(
    tmp_path: Path,
) -> None:
    pki = write_pki(tmp_path / "pki")
    security = ServerSecurity(
        cert=pki.server_cert, key=pki.server_key, client_ca=pki.ca, token_file=pki.token
    )
    client = ClientSecurity(
        ca=pki.ca, cert=pki.client_cert, key=pki.client_key, token_file=pki.token
    )
    async with served(Echo(), security=security) as server:
        assert server.address.startswith("grpcs://")
        async with RemoteParticipant(server.address, security=client) as remote:
            await remote.initialize(setup())
            assert (await remote.do_step(0.0, 0.1, {"frame": bytes(FRAME)}))["size"] == FRAME
            await remote.terminate()
        stranger = RemoteParticipant(server.address, connect_timeout=1.0)
        with pytest.raises(ParticipantError):
            await stranger.open()
        await stranger.close()
