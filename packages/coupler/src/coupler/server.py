"""The participant runtime: serves one ``Participant`` over gRPC.

``serve()`` runs a grpc.aio server with the component service, the standard health service
(NOT_SERVING until the participant is open and described, again on shutdown) and server
reflection, and stops gracefully on SIGTERM/SIGINT.

Rules every participant gets for free: one run at a time (a second Initialize during a run is
FAILED_PRECONDITION), DoStep before Initialize is FAILED_PRECONDITION, an unknown channel or a
wrong type is INVALID_ARGUMENT naming the channel and the expected type, and an exception inside
the participant is INTERNAL with its message while the server keeps serving.
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import NoReturn, TypeVar

import grpc
import structlog
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection

from coupler import values
from coupler.channels import Description
from coupler.errors import ChannelValueError, ParticipantUnavailable, ScenarioError
from coupler.participant import Participant
from coupler.v1 import component_pb2 as pb
from coupler.v1 import component_pb2_grpc as pb_grpc

log = structlog.get_logger("coupler.server")
SERVICE_NAME = pb.DESCRIPTOR.services_by_name["GRPCComponentService"].full_name
T = TypeVar("T")


class _Servicer(pb_grpc.GRPCComponentServiceServicer):
    """Applies the protocol's rules around one participant."""

    def __init__(self, participant: Participant) -> None:
        self.participant = participant
        self._codec: values.Codec | None = None
        self.run_id: str | None = None
        self._lock = asyncio.Lock()

    def ready(self, description: Description) -> None:
        """The participant is open and described: calls are answered from now on."""
        self._codec = values.Codec(description)

    @property
    def codec(self) -> values.Codec:
        if self._codec is None:
            raise _NotReady
        return self._codec

    async def Describe(
        self, request: pb.DescribeRequest, context: grpc.aio.ServicerContext
    ) -> pb.DescribeResponse:
        return values.description_to_pb(self.codec.description)

    async def Initialize(
        self, request: pb.InitializeRequest, context: grpc.aio.ServicerContext
    ) -> pb.InitializeResponse:
        async with self._lock:
            await _guard(context, lambda: self.codec)
            if self.run_id is not None:
                await context.abort(
                    grpc.StatusCode.FAILED_PRECONDITION,
                    f"participant '{self.codec.description.name}' is already in run "
                    f"'{self.run_id}'; a participant serves one run at a time "
                    f"(Terminate that run first)",
                )
            setup = await _guard(context, lambda: values.initialize_from_pb(request, self.codec))
            outputs = await _guard(context, lambda: self.participant.initialize(setup))
            self.run_id = setup.run_id or "unnamed"
            log.info("run_initialized", run_id=self.run_id, participant=self.codec.description.name)
            return await _guard(context, lambda: values.initialize_response(outputs, self.codec))

    async def DoStep(
        self, request: pb.DoStepRequest, context: grpc.aio.ServicerContext
    ) -> pb.DoStepResponse:
        async with self._lock:
            return await self._step(request, context)

    async def StepStream(
        self,
        request_iterator: AsyncIterator[pb.DoStepRequest],
        context: grpc.aio.ServicerContext,
    ) -> AsyncIterator[pb.DoStepResponse]:
        async for request in request_iterator:
            async with self._lock:
                response = await self._step(request, context)
            yield response

    async def _step(
        self, request: pb.DoStepRequest, context: grpc.aio.ServicerContext
    ) -> pb.DoStepResponse:
        await _guard(context, lambda: self.codec)
        if self.run_id is None:
            await context.abort(
                grpc.StatusCode.FAILED_PRECONDITION,
                f"DoStep before Initialize: participant '{self.codec.description.name}' "
                f"has no run (call Initialize first)",
            )
        time, step, inputs = await _guard(context, lambda: values.step_from_pb(request, self.codec))
        if not step > 0:
            await context.abort(
                grpc.StatusCode.INVALID_ARGUMENT, f"step_size must be positive, got {step}"
            )
        outputs = await _guard(context, lambda: self.participant.do_step(time, step, inputs))
        return await _guard(context, lambda: values.step_response(outputs, self.codec))

    async def Terminate(
        self, request: pb.TerminateRequest, context: grpc.aio.ServicerContext
    ) -> pb.TerminateResponse:
        async with self._lock:
            await self.end_run(values.terminate_reason(request))
        return pb.TerminateResponse()

    async def end_run(self, reason: str) -> None:
        """Terminate the current run, if any; idempotent."""
        if self.run_id is None:
            return
        run_id, self.run_id = self.run_id, None
        try:
            await self.participant.terminate(reason)
        finally:
            log.info("run_terminated", run_id=run_id, reason=reason or "requested")


class _NotReady(Exception):
    """A call arrived before the participant was open and described."""


async def _guard(context: grpc.aio.ServicerContext, call: Callable[[], T | Awaitable[T]]) -> T:
    """Runs ``call``; maps what it raises onto a status code with an actionable message."""
    try:
        result = call()
        if isinstance(result, Awaitable):
            return await result
        return result
    except _NotReady:
        await _abort(context, grpc.StatusCode.UNAVAILABLE, "participant is starting; not ready yet")
    except (ChannelValueError, ScenarioError) as exc:
        await _abort(context, grpc.StatusCode.INVALID_ARGUMENT, str(exc))
    except ParticipantUnavailable as exc:
        await _abort(context, grpc.StatusCode.UNAVAILABLE, str(exc))
    except asyncio.CancelledError:
        raise
    except Exception as exc:  # the participant's own failure: report it, keep serving
        log.exception("participant_failed")
        await _abort(context, grpc.StatusCode.INTERNAL, f"{type(exc).__name__}: {exc}")


async def _abort(
    context: grpc.aio.ServicerContext, code: grpc.StatusCode, message: str
) -> NoReturn:
    await context.abort(code, message)
    raise AssertionError("unreachable")  # context.abort raises


class ParticipantServer:
    """A running participant server; ``serve()`` is the usual way to get one."""

    def __init__(self, participant: Participant, *, host: str = "127.0.0.1", port: int = 0):
        self.participant = participant
        self.host = host
        self.requested_port = port
        self.port = 0
        self.health = health.aio.HealthServicer()
        self._server: grpc.aio.Server | None = None
        self._servicer: _Servicer | None = None

    @property
    def address(self) -> str:
        """``grpc://host:port`` of the running server."""
        return f"grpc://{self.host}:{self.port}"

    async def start(self) -> int:
        """Bind, open the participant, describe it, then report SERVING. Returns the port."""
        server = grpc.aio.server()
        self._server = server
        await self._set_health(health_pb2.HealthCheckResponse.NOT_SERVING)
        self._servicer = _Servicer(self.participant)
        pb_grpc.add_GRPCComponentServiceServicer_to_server(self._servicer, server)
        health_pb2_grpc.add_HealthServicer_to_server(self.health, server)
        reflection.enable_server_reflection(
            (SERVICE_NAME, health.SERVICE_NAME, reflection.SERVICE_NAME), server
        )
        self.port = server.add_insecure_port(f"{self.host}:{self.requested_port}")
        await server.start()
        await self.participant.open()
        description = await self.participant.describe()
        self._servicer.ready(description)
        await self._set_health(health_pb2.HealthCheckResponse.SERVING)
        log.info("participant_serving", participant=description.name, address=self.address)
        return self.port

    async def stop(self, grace: float = 2.0) -> None:
        """NOT_SERVING, end the active run, stop the server, close the participant."""
        await self._set_health(health_pb2.HealthCheckResponse.NOT_SERVING)
        if self._servicer is not None:
            try:
                await self._servicer.end_run("participant shutting down")
            except Exception:
                log.exception("terminate_on_shutdown_failed")
        if self._server is not None:
            await self._server.stop(grace)
        await self.participant.close()
        log.info("participant_stopped", address=self.address)

    async def wait(self) -> None:
        if self._server is not None:
            await self._server.wait_for_termination()

    async def _set_health(self, status: health_pb2.HealthCheckResponse.ServingStatus) -> None:
        await self.health.set("", status)
        await self.health.set(SERVICE_NAME, status)


async def serve(
    participant: Participant,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    on_started: Callable[[ParticipantServer], None] | None = None,
) -> None:
    """Serve ``participant`` until SIGTERM or SIGINT, then shut down gracefully."""
    server = ParticipantServer(participant, host=host, port=port)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    try:
        await server.start()
        if on_started is not None:
            on_started(server)
        await stop.wait()
    finally:
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.remove_signal_handler(sig)
        await server.stop()


__all__ = ["ParticipantServer", "serve"]
