"""The floors: bare grpc.aio round trips to trivial servers (processes answering the same
messages a participant answers: unary DoStep and the bidi StepStream; a gain participant's
sizes, a camera frame's, or empty), which ``suite.py --raw-server`` starts.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Sequence
from typing import Any

from sections.common import STEP


def _raw_messages() -> tuple[Any, Any]:
    """A request and a response of the sizes the gain participant exchanges."""
    from coupler.v1 import component_pb2 as pb

    request = pb.DoStepRequest(
        current_time=0.0, step_size=STEP, run_id="bench", run_secret=bytes(32)
    )
    request.inputs.add(channel="u", real=1.0)
    response = pb.DoStepResponse()
    for name, kind, value in [
        ("y", "real", 4.0),
        ("x", "real", 0.01),
        ("count", "integer", 0),
        ("inverted", "boolean", True),
        ("echo", "text", ""),
        ("blob_out", "binary", b""),
    ]:
        response.outputs.add(channel=name, **{kind: value})
    return request, response


def _frame_messages(direction: str) -> tuple[Any, Any]:
    """A step of a camera's frame, FRAME_BYTES in a binary value: ``out`` of a participant
    that sends it (the bridge: a small request, the frame in the response), ``in`` of one that
    receives it (the map: the frame in the request, an empty response)."""
    from coupler.v1 import component_pb2 as pb

    frame = bytes(range(256)) * (FRAME_BYTES // 256)
    request = pb.DoStepRequest(current_time=0.0, step_size=FRAME_STEP, run_id="bench")
    response = pb.DoStepResponse()
    if direction == "out":
        response.outputs.add(channel="front", binary=frame)
    else:
        request.inputs.add(channel="camera", binary=frame)
    return request, response


def _messages(kind: str) -> tuple[Any, Any]:
    """A step's request and response: the gain participant's sizes (``kind`` empty), a camera
    frame's (``out``, ``in``: ``_frame_messages``) or ``minimal`` (empty messages)."""
    if kind == "minimal":
        from coupler.v1 import component_pb2 as pb

        return pb.DoStepRequest(), pb.DoStepResponse()
    return _frame_messages(kind) if kind else _raw_messages()


async def raw_server(where: str, frames: str = "") -> None:
    """A trivial GRPCComponentService on a port (``where`` a number) or a unix socket (``where``
    ``unix:PATH``), or one on each of several ports (``where`` comma-separated, one process):
    every step answered with the same outputs (``frames`` ``out``: a camera frame; ``in``:
    nothing, its requests carry one; ``minimal``: an empty response)."""
    if "," in where:
        await asyncio.gather(*(raw_server(w, frames) for w in where.split(",")))
        return
    import grpc

    from coupler.v1 import component_pb2_grpc as rpc

    _, response = _messages(frames)

    class Trivial(rpc.GRPCComponentServiceServicer):  # type: ignore[misc]
        async def DoStep(self, request: Any, context: Any) -> Any:
            return response

        async def StepStream(self, requests: Any, context: Any) -> AsyncIterator[Any]:
            async for _ in requests:
                yield response

    server = grpc.aio.server(options=FRAME_GRPC_OPTIONS)
    rpc.add_GRPCComponentServiceServicer_to_server(Trivial(), server)
    server.add_insecure_port(f"127.0.0.1:{where}" if where.isdigit() else where)
    await server.start()
    await server.wait_for_termination()


async def raw_floor(
    servers: Sequence[int | str], steps: int, *, stream: bool, messages: str = ""
) -> float:
    """Steps/s of bare grpc.aio round trips to every server (a port, or ``unix:PATH``) per
    step (gathered); requests of the kind ``messages`` (``_messages``)."""
    import grpc

    from coupler.v1 import component_pb2_grpc as rpc

    request, _ = _messages(messages)
    targets = [f"127.0.0.1:{s}" if isinstance(s, int) else s for s in servers]
    channels = [grpc.aio.insecure_channel(t) for t in targets]
    try:
        for channel in channels:
            await asyncio.wait_for(channel.channel_ready(), 30)
        stubs = [rpc.GRPCComponentServiceStub(c) for c in channels]
        if stream:
            calls = [stub.StepStream() for stub in stubs]

            async def trip(call: Any) -> Any:
                await call.write(request)
                return await call.read()

            async def once() -> None:
                if len(calls) == 1:
                    await trip(calls[0])
                else:
                    await asyncio.gather(*(trip(c) for c in calls))
        else:

            async def once() -> None:
                if len(stubs) == 1:
                    await stubs[0].DoStep(request)
                else:
                    await asyncio.gather(*(s.DoStep(request) for s in stubs))

        for _ in range(50):
            await once()
        started = time.perf_counter()
        for _ in range(steps):
            await once()
        rate = steps / (time.perf_counter() - started)
        if stream:
            for call in calls:
                await call.done_writing()
        return rate
    finally:
        for channel in channels:
            await channel.close()


FRAME_BYTES = 800 * 600 * 3
"""An 800 x 600 RGB frame (the Image message adds a few bytes)."""


FRAME_STEP = 0.2
"""OpenRails' lockstep step: frames at 5 Hz of simulated time."""


FRAME_GRPC_OPTIONS = [("grpc.max_receive_message_length", 8 * 1024 * 1024)]


async def raw_frames(sender: str, receiver: str, steps: int) -> float:
    """Steps/s of bare grpc.aio bidi streams moving a frame per step as the frames case does:
    one from a sender (its response), one to a receiver (its request), both each step; each
    server at a grpc target (``unix:PATH``)."""
    import grpc

    from coupler.v1 import component_pb2_grpc as rpc

    pairs = [(sender, _frame_messages("out")[0]), (receiver, _frame_messages("in")[0])]
    channels = [
        grpc.aio.insecure_channel(target, options=FRAME_GRPC_OPTIONS) for target, _ in pairs
    ]
    try:
        for channel in channels:
            await asyncio.wait_for(channel.channel_ready(), 30)
        calls = [rpc.GRPCComponentServiceStub(c).StepStream() for c in channels]
        requests = [request for _, request in pairs]

        async def trip(call: Any, request: Any) -> Any:
            await call.write(request)
            return await call.read()

        async def once() -> None:
            await asyncio.gather(*(trip(c, r) for c, r in zip(calls, requests, strict=True)))

        for _ in range(10):
            await once()
        started = time.perf_counter()
        for _ in range(steps):
            await once()
        rate = steps / (time.perf_counter() - started)
        for call in calls:
            await call.done_writing()
        return rate
    finally:
        for channel in channels:
            await channel.close()
