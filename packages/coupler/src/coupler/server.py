"""The participant runtime: serves one ``Participant`` over gRPC.

``serve()`` runs a grpc.aio server with the component service and the standard health service
(NOT_SERVING until the participant is open and described, again on shutdown), and stops
gracefully on SIGTERM/SIGINT.

Rules every participant gets for free (docs/protocol.md has the table):

- one run at a time: Initialize during a run is FAILED_PRECONDITION (without revealing the
  active run's id); DoStep before Initialize is FAILED_PRECONDITION;
- runs are leases: DoStep, StepStream and Terminate must carry the active run's id (another id
  is FAILED_PRECONDITION); the run ends on Terminate, when its StepStream ends without
  Terminate, or after ``lease`` seconds without a call -- then the next run may start; a lease
  is at most ``durations.MAX_LEASE`` (24 h), a NaN, infinite or negative one is INVALID_ARGUMENT;
- runs are secret: Initialize brings the run's secret (16 to 256 bytes, else INVALID_ARGUMENT),
  every later call of the run carries it (compared in constant time). A call with the run's id
  and without its secret is PERMISSION_DENIED and remembered as an intrusion (peer, call, time);
  the owner's next call of the run is then ABORTED naming it, so the run fails (Terminate
  still ends the run). The secret is never logged and never shown to the participant;
- an unknown channel or a wrong type is INVALID_ARGUMENT naming the channel and the expected
  type; an exception inside the participant is INTERNAL with its message while the server
  keeps serving; a participant that raises ``EndRun`` answers with ``terminate`` set;
- sizes: a value over the maximum its channel declares (``Channel.max_bytes``), received or
  about to be sent, and a message over the message limit are RESOURCE_EXHAUSTED naming the
  channel; the server's gRPC limits are derived from the declarations (``wire.served_limits``:
  received, the parameters' and inputs' maxima together; sent, the outputs'; the default,
  ``max_message_bytes``, where one is undeclared), plus framing.
"""

from __future__ import annotations

import asyncio
import hmac
import math
import os
import signal
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NoReturn, TypeAlias, TypeVar

import grpc
import structlog
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection

from coupler import durations, ports, wire
from coupler.channels import Description
from coupler.costs import StepMeter
from coupler.errors import (
    ChannelValueError,
    MessageTooLarge,
    ParticipantUnavailable,
    ScenarioError,
    ValueTooLarge,
)
from coupler.participant import HEALTH_REASON, EndRun, Participant
from coupler.security import ServerSecurity
from coupler.step_socket import STEP_SOCKET_SUFFIX, SocketContext, StepSocket
from coupler.v1 import component_pb2_grpc as pb_grpc
from coupler.values import MAX_MESSAGE_BYTES, ValuePolicy

log = structlog.get_logger("coupler.server")
SERVICE_NAME = wire.SERVICE_NAME
DEFAULT_LEASE = 60.0
"""Lease of a run whose Initialize asks for none [s]."""
T = TypeVar("T")


@dataclass(eq=False)
class _Run:
    """The active run: its id, secret, lease and when it was last heard of."""

    id: str
    secret: bytes = field(repr=False)
    lease: float
    reached: float
    """Simulated time the run has reached [s] (after its last step)."""
    intrusion: str | None = None
    """Why the run is no longer trusted: the first call of it without its secret."""
    intrusions: int = 0
    started: float = field(default_factory=time.monotonic)
    last_call: float = field(default_factory=time.monotonic)
    busy: int = 0
    """Steps in progress: a run inside a step is not silent."""


@dataclass(eq=False)
class _Stream:
    """One step loop: a StepStream, or a connection to the step socket."""

    carried: _Run | None = None
    """The run this loop carries: its owner's requests came on it."""
    answers: wire.StepAnswers | None = None
    """This loop's prepared answer."""


class _Servicer(pb_grpc.GRPCComponentServiceServicer):
    """Applies the protocol's rules around one participant."""

    def __init__(self, participant: Participant, max_message_bytes: int) -> None:
        self.participant = participant
        self.policy = ValuePolicy(max_message_bytes=max_message_bytes)
        self._codec: wire.Codec | None = None
        self.run: _Run | None = None
        self._lock = asyncio.Lock()
        self._watchdog: asyncio.Task[None] | None = None
        self.stopping = False
        """The server is shutting down: calls are refused as UNAVAILABLE."""

    @property
    def run_id(self) -> str | None:
        """The active run's id, or None."""
        return self.run.id if self.run is not None else None

    def ready(self, description: Description) -> None:
        """The participant is open and described: calls are answered from now on."""
        self._codec = wire.Codec(description, self.policy)

    @property
    def codec(self) -> wire.Codec:
        if self._codec is None:
            raise _NotReady
        return self._codec

    @property
    def name(self) -> str:
        return self.codec.description.name

    async def Describe(
        self, request: wire.DescribeRequest, context: grpc.aio.ServicerContext
    ) -> wire.DescribeResponse:
        await _guard(context, lambda: self.codec)
        return wire.description_to_pb(self.codec.description)

    async def Initialize(
        self, request: wire.InitializeRequest, context: grpc.aio.ServicerContext
    ) -> wire.InitializeResponse:
        async with self._lock:
            await _guard(context, lambda: self.codec)
            if self.run is not None:
                idle = time.monotonic() - self.run.last_call
                await context.abort(
                    grpc.StatusCode.FAILED_PRECONDITION,
                    f"participant '{self.name}' is in another run (started "
                    f"{time.monotonic() - self.run.started:.0f} s ago, last call {idle:.0f} s "
                    f"ago; its lease ends it after {self.run.lease:g} s without calls); a "
                    f"participant serves one run at a time: Terminate that run or wait",
                )
            secret = request.run_secret
            if not wire.MIN_SECRET <= len(secret) <= wire.MAX_SECRET:
                await _abort(
                    context,
                    grpc.StatusCode.INVALID_ARGUMENT,
                    f"run_secret must be {wire.MIN_SECRET} to {wire.MAX_SECRET} random bytes, got "
                    f"{len(secret)}: every later call of the run must carry it (docs/protocol.md)",
                )
            setup = await _guard(context, lambda: wire.initialize_from_pb(request, self.codec))
            if setup.lease and (why := durations.problem(setup.lease, durations.MAX_LEASE)):
                await _abort(
                    context,
                    grpc.StatusCode.INVALID_ARGUMENT,
                    f"lease_seconds {why} (or 0: the participant's default, {DEFAULT_LEASE:g} s)",
                )
            times = {"start_time": setup.start_time, "step_size": setup.step_size}
            if setup.stop_time is not None:
                times["stop_time"] = setup.stop_time
            if wrong := {name: t for name, t in times.items() if not math.isfinite(t)}:
                await _abort(
                    context,
                    grpc.StatusCode.INVALID_ARGUMENT,
                    ", ".join(f"{name} must be finite, got {t!r}" for name, t in wrong.items()),
                )
            outputs = await _guard(context, lambda: self.participant.initialize(setup))
            self.run = run = _Run(
                id=setup.run_id,
                secret=secret,
                lease=setup.lease or DEFAULT_LEASE,
                reached=setup.start_time,
            )
            self._watchdog = asyncio.create_task(self._watch(run), name=f"lease-{run.id}")
            log.info("run_initialized", run_id=run.id, participant=self.name, lease_s=run.lease)
            return await _guard(context, lambda: wire.initialize_response(outputs, self.codec))

    async def DoStep(
        self, request: wire.StepRequest, context: grpc.aio.ServicerContext
    ) -> wire.Answer:
        async with self._lock:
            return await self._step(request, context)

    async def StepStream(
        self,
        request_iterator: AsyncIterator[wire.StepRequest],
        context: grpc.aio.ServicerContext,
    ) -> AsyncIterator[wire.Answer]:
        stream = _Stream()
        try:
            async for received in request_iterator:
                yield await self.stream_step(stream, received, context)
        finally:
            self.stream_ended(stream, "its step stream ended without Terminate")

    def open_stream(self) -> _Stream:
        """A new step loop's state (``step_socket.StepLoop``)."""
        return _Stream()

    async def stream_step(
        self, stream: _Stream, received: wire.StepRequest, context: _Context
    ) -> wire.Answer:
        """One request of a step loop -- a StepStream's or a step socket connection's: the
        loop that carries the run's owner's requests carries the run."""
        async with self._lock:
            run = self.run
            request = received[0]
            if (
                stream.carried is not run
                and run is not None
                and request.run_id == run.id
                and hmac.compare_digest(request.run_secret, run.secret)
            ):
                stream.carried = run  # this loop belongs to the run's owner
            if stream.answers is None and self._codec is not None:
                stream.answers = wire.StepAnswers(self._codec)
            return await self._step(received, context, stream.answers)

    def stream_ended(self, stream: _Stream, why: str) -> None:
        """A step loop ended (finished, broken or cancelled): before Terminate, the run goes
        with it."""
        carried = stream.carried
        if carried is not None and carried is self.run:
            self._end_later(carried, why)

    async def _step(
        self,
        received: wire.StepRequest,
        context: _Context,
        answers: wire.StepAnswers | None = None,
    ) -> wire.Answer:
        """One step: the protocol's checks, the inputs decoded, the participant's step, its
        outputs encoded (into ``answers``' prepared message on a stream). No lambdas, no
        ``_guard`` per stage: one ``try`` around each stage that can fail, ``_refuse`` maps
        what it raises (the per-step cost is docs/performance-history.md's profile). ``received`` is
        the request and its long Binary inputs, cut out of its bytes (``wire.step_request``);
        the answer may be serialized already, in pieces (``wire.step_response``)."""
        request, large = received
        codec = self._codec
        if codec is None:
            await _refuse(context, _NotReady())
        run = self.run
        if self.stopping:
            await _abort(
                context,
                grpc.StatusCode.UNAVAILABLE,
                f"participant '{self.name}' is shutting down (its process was asked to stop)",
            )
        if run is None:
            await _abort(
                context,
                grpc.StatusCode.FAILED_PRECONDITION,
                f"DoStep before Initialize: participant '{self.name}' has no run "
                f"(call Initialize first; a run also ends when its lease expires)",
            )
        if request.run_id != run.id:
            await _abort(
                context,
                grpc.StatusCode.FAILED_PRECONDITION,
                f"DoStep for run '{request.run_id}', which is not participant '{self.name}'s "
                f"active run; only the orchestrator that initialized the run may step it",
            )
        if run.intrusion is not None or not hmac.compare_digest(request.run_secret, run.secret):
            await self._untrusted(run, request.run_secret, "DoStep", context)
        try:
            step = wire.step_from_pb(request, codec, large)
        except Exception as exc:
            await _refuse(context, exc)
        if not (0 < step.step < math.inf and math.isfinite(step.time)):
            await _abort(
                context,
                grpc.StatusCode.INVALID_ARGUMENT,
                f"step_size must be finite and positive and current_time finite, got "
                f"step_size={step.step!r}, current_time={step.time!r}",
            )
        run.busy += 1
        cost = StepMeter()
        cost.start()
        try:
            outputs = await self.participant.do_step(step.time, step.step, step.inputs)
        except EndRun as end:
            cost.stop()
            last, reason = end.outputs, end.reason
            log.info("run_end_requested", run_id=run.id, participant=self.name, reason=reason)
            return await _guard(
                context,
                lambda: wire.step_response(last, codec, terminate_reason=reason, cost=cost),
            )
        except Exception as exc:
            await _refuse(context, exc)
        finally:
            cost.stop()
            run.busy -= 1
            run.last_call = time.monotonic()
        run.reached = step.time + step.step
        try:
            if answers is not None:
                return answers.answer(outputs, cost)
            return wire.step_response(outputs, codec, cost=cost)
        except Exception as exc:
            await _refuse(context, exc)

    async def Terminate(
        self, request: wire.TerminateRequest, context: grpc.aio.ServicerContext
    ) -> wire.TerminateResponse:
        async with self._lock:
            run = self.run
            if run is not None and request.run_id != run.id:
                await _abort(
                    context,
                    grpc.StatusCode.FAILED_PRECONDITION,
                    f"Terminate for run '{request.run_id}', which is not participant "
                    f"'{self.name}'s active run; nothing was ended",
                )
            if run is not None and not hmac.compare_digest(request.run_secret, run.secret):
                await self._untrusted(run, request.run_secret, "Terminate", context)
            await self.end_run(request.reason)
            if run is not None and run.intrusion is not None:
                await _abort(context, grpc.StatusCode.ABORTED, self._refusal(run))
        return wire.TerminateResponse()

    async def _untrusted(self, run: _Run, secret: bytes, call: str, context: _Context) -> NoReturn:
        """Refuses a call of ``run``: without the run's secret it is an intrusion
        (PERMISSION_DENIED, remembered); from the owner of a run that saw one, ABORTED."""
        if hmac.compare_digest(secret, run.secret):
            await _abort(context, grpc.StatusCode.ABORTED, self._refusal(run))
        peer = context.peer() or "an unknown address"
        run.intrusions += 1
        if run.intrusion is None:
            how = "without this run's secret" if not secret else "with a wrong secret"
            run.intrusion = (
                f"{self.name} refused the run: a call {how} arrived from {peer} ({call} at "
                f"t={run.reached:g} s); the run is no longer trusted"
            )
        log.warning("run_intrusion", run_id=run.id, participant=self.name, peer=peer, call=call)
        await _abort(
            context,
            grpc.StatusCode.PERMISSION_DENIED,
            f"{call} refused: it names participant '{self.name}'s active run but does not carry "
            f"that run's secret (run_secret, docs/protocol.md); the run's owner will be told",
        )

    @staticmethod
    def _refusal(run: _Run) -> str:
        """What the owner of a run that saw an intrusion is told."""
        more = run.intrusions - 1
        return f"{run.intrusion}" + (f" ({more} more such calls since)" if more > 0 else "")

    async def end_run(self, reason: str) -> None:
        """Terminate the active run, if any; idempotent. The caller holds the lock."""
        run, self.run = self.run, None
        if run is None:
            return
        watchdog, self._watchdog = self._watchdog, None
        if watchdog is not None and watchdog is not asyncio.current_task():
            watchdog.cancel()
        try:
            await self.participant.terminate(reason)
        finally:
            log.info("run_terminated", run_id=run.id, reason=reason or "requested")

    async def close_run(self, reason: str) -> None:
        """End whatever run is active (shutdown)."""
        async with self._lock:
            await self.end_run(reason)

    async def _end(self, run: _Run, reason: str) -> None:
        async with self._lock:
            if self.run is run:
                log.warning("run_ended_by_participant", run_id=run.id, why=reason)
                await self.end_run(reason)

    def _end_later(self, run: _Run, reason: str) -> None:
        """End ``run`` from a task of its own (safe from a cancelled handler)."""
        task = asyncio.get_running_loop().create_task(self._end(run, reason))
        _BACKGROUND.add(task)
        task.add_done_callback(_BACKGROUND.discard)

    async def _watch(self, run: _Run) -> None:
        """Ends ``run`` after ``run.lease`` seconds without a call."""
        while self.run is run:
            silent = time.monotonic() - run.last_call
            if run.busy or silent < run.lease:
                await asyncio.sleep(max(run.lease - silent, 0.05))
                continue
            await self._end(run, f"lease expired: no call for {run.lease:g} s")
            return


_BACKGROUND: set[asyncio.Task[None]] = set()


def _add_service(servicer: _Servicer, server: grpc.aio.Server) -> None:
    """The component service as protobuf's generated code adds it, but a step's request is
    parsed by ``wire.step_request`` (its long Binary inputs cut out of its bytes with one copy
    each) and its answer sent by ``wire.serialized`` (a message, or its bytes with long Binary
    outputs joined after it): protobuf would copy such values twice each way."""
    unary, stream = grpc.unary_unary_rpc_method_handler, grpc.stream_stream_rpc_method_handler
    handlers = {
        "Describe": unary(
            servicer.Describe,
            request_deserializer=wire.DescribeRequest.FromString,
            response_serializer=wire.DescribeResponse.SerializeToString,
        ),
        "Initialize": unary(
            servicer.Initialize,
            request_deserializer=wire.InitializeRequest.FromString,
            response_serializer=wire.InitializeResponse.SerializeToString,
        ),
        "DoStep": unary(
            servicer.DoStep,
            request_deserializer=wire.step_request,
            response_serializer=wire.serialized,
        ),
        "StepStream": stream(
            servicer.StepStream,
            request_deserializer=wire.step_request,
            response_serializer=wire.serialized,
        ),
        "Terminate": unary(
            servicer.Terminate,
            request_deserializer=wire.TerminateRequest.FromString,
            response_serializer=wire.TerminateResponse.SerializeToString,
        ),
    }
    server.add_generic_rpc_handlers((grpc.method_handlers_generic_handler(SERVICE_NAME, handlers),))
    server.add_registered_method_handlers(SERVICE_NAME, handlers)


_Context: TypeAlias = grpc.aio.ServicerContext | SocketContext


class _NotReady(Exception):
    """A call arrived before the participant was open and described."""


async def _guard(context: _Context, call: Callable[[], T | Awaitable[T]]) -> T:
    """Runs ``call``; maps what it raises onto a status code with an actionable message."""
    try:
        result = call()
        if isinstance(result, Awaitable):
            return await result
        return result
    except EndRun:
        raise
    except Exception as exc:
        await _refuse(context, exc)


async def _refuse(context: _Context, exc: Exception) -> NoReturn:
    """Fails the call with the status code and message for ``exc``, raised by the runtime's or
    the participant's code while serving it."""
    if isinstance(exc, _NotReady):
        await _abort(context, grpc.StatusCode.UNAVAILABLE, "participant is starting; not ready yet")
    if isinstance(exc, MessageTooLarge | ValueTooLarge):
        await _abort(context, grpc.StatusCode.RESOURCE_EXHAUSTED, str(exc))
    if isinstance(exc, ChannelValueError | ScenarioError):
        await _abort(context, grpc.StatusCode.INVALID_ARGUMENT, str(exc))
    if isinstance(exc, ParticipantUnavailable):  # the caller names the participant and the call
        await _abort(context, grpc.StatusCode.UNAVAILABLE, exc.detail)
    # the participant's own failure: report it, keep serving
    log.exception("participant_failed", exc_info=exc)
    await _abort(context, grpc.StatusCode.INTERNAL, f"{type(exc).__name__}: {exc}")


async def _abort(context: _Context, code: grpc.StatusCode, message: str) -> NoReturn:
    await context.abort(code, message)
    raise AssertionError("unreachable")  # context.abort raises


class _Health(health.aio.HealthServicer):
    """The standard health service; a NOT_SERVING answer carries ``reason`` as trailing
    metadata (``HEALTH_REASON``), so probes can say why."""

    reason = ""

    async def Check(
        self, request: health_pb2.HealthCheckRequest, context: grpc.aio.ServicerContext
    ) -> health_pb2.HealthCheckResponse:
        response: health_pb2.HealthCheckResponse = await super().Check(request, context)
        if self.reason and response.status != health_pb2.HealthCheckResponse.SERVING:
            ascii_reason = self.reason.encode("ascii", "backslashreplace").decode()
            context.set_trailing_metadata(((HEALTH_REASON, ascii_reason),))
        return response


class ParticipantServer:
    """A running participant server; ``serve()`` is the usual way to get one."""

    def __init__(
        self,
        participant: Participant,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        reflection: bool = False,
        security: ServerSecurity | None = None,
        unix_socket: Path | None = None,
        max_message_bytes: int = MAX_MESSAGE_BYTES,
    ):
        self.participant = participant
        self.max_message_bytes = max_message_bytes
        """The values of one message, Binary and String together, may have this many bytes
        where the participant's channels do not all declare a maximum (``Channel.max_bytes``);
        more fails the call as RESOURCE_EXHAUSTED naming the channel (docs/protocol.md)."""
        self.limits = wire.MessageLimits(max_message_bytes, max_message_bytes)
        """What the server lets through (``wire.served_limits`` once the participant is
        described; until then ``max_message_bytes`` either way)."""
        self.unix_socket = Path(os.path.abspath(unix_socket)) if unix_socket else None
        self.host = host
        self.requested_port = port
        self.reflection = reflection
        self.security = security or ServerSecurity()
        self.port = 0
        self.health_port: int | None = None
        """Port of the plaintext health-only server, when ``security.health_port`` asks for one."""
        self.health = _Health()
        self._stopping = False
        self._reported = False
        self._name = ""
        self._server: grpc.aio.Server | None = None
        self._health_server: grpc.aio.Server | None = None
        self._servicer: _Servicer | None = None
        self._step_socket: StepSocket | None = None

    @property
    def name(self) -> str:
        """The participant's name once it is described (``start``), else ``""``."""
        return self._name

    @property
    def step_socket(self) -> Path | None:
        """Where the participant also serves its step loop without gRPC (``PATH.steps`` beside
        its unix socket ``PATH``, when it serves on one without TLS), or None."""
        return self._step_socket.path if self._step_socket is not None else None

    @property
    def address(self) -> str:
        """``grpc://host:port`` (``grpcs://`` with TLS, ``unix:///path`` on a unix socket)."""
        if self.unix_socket is not None:
            return f"unix://{self.unix_socket}"
        scheme = "grpcs" if self.security.tls else "grpc"
        return f"{scheme}://{ports.host_port(self.host, self.port)}"

    async def start(self) -> int:
        """Bind, open the participant, describe it, then report its health (SERVING unless
        ``Participant.watch_health`` says otherwise). Returns the port.

        The server binds before the participant is open (its health says NOT_SERVING
        meanwhile), with the default limits; when the description's declared maxima give
        others (``wire.served_limits``), it is bound again on the same address with those,
        since gRPC fixes a server's limits when it is made."""
        # a unix socket stays on this machine, protected by its file permissions
        warning = self.security.check("localhost" if self.unix_socket else self.host)
        if warning:
            log.warning("insecure_interface", host=self.host, detail=warning)
        credentials = self.security.credentials()
        await self._set_health(health_pb2.HealthCheckResponse.NOT_SERVING)
        self._servicer = _Servicer(self.participant, self.max_message_bytes)
        self._server = await self._serve(credentials, self.requested_port)
        if self.security.health_port is not None:
            await self._start_health_server(self.security.health_port)
        await self.participant.open()
        description = await self.participant.describe()
        limits = wire.served_limits(description, self.max_message_bytes)
        if limits != self.limits:
            self.limits = limits
            server, self._server = self._server, None
            await server.stop(0)
            self._server = await self._serve(credentials, self.port)
        if await self._serve_steps():
            assert self._step_socket is not None
            offered = replace(description.capabilities, step_socket=str(self._step_socket.path))
            description = replace(description, capabilities=offered)
        self._servicer.ready(description)
        self._name = description.name
        await self.participant.watch_health(self._report_health)
        return self.port

    async def _serve(
        self, credentials: grpc.ServerCredentials | None, port: int
    ) -> grpc.aio.Server:
        """A started gRPC server of the participant and its health, with ``self.limits``, on
        the unix socket or on ``port`` (0: a free one, then ``self.port``)."""
        assert self._servicer is not None
        server = grpc.aio.server(
            interceptors=self.security.interceptors(),
            options=ports.GRPC_SERVER_OPTIONS + self.limits.options(),
        )
        _add_service(self._servicer, server)
        health_pb2_grpc.add_HealthServicer_to_server(self.health, server)
        if self.reflection:
            reflection.enable_server_reflection(
                (SERVICE_NAME, health.SERVICE_NAME, reflection.SERVICE_NAME), server
            )
        if self.unix_socket is not None:
            ports.add_grpc_socket(server, self.unix_socket, credentials, "the participant")
        else:
            self.port = ports.add_grpc_port(server, self.host, port, credentials, "the participant")
        await server.start()
        return server

    async def _serve_steps(self) -> bool:
        """Serve the step socket beside the unix socket (not for TLS: its clients want the
        channel's protection); whether it serves."""
        if self.unix_socket is None or self.security.tls or self._servicer is None:
            return False
        path = self.unix_socket.with_name(self.unix_socket.name + STEP_SOCKET_SUFFIX)
        if len(os.fsencode(path)) > ports.SOCKET_PATH_MAX:
            log.warning(
                "no_step_socket",
                path=str(path),
                why=f"longer than {ports.SOCKET_PATH_MAX} bytes; steps travel over StepStream",
            )
            return False
        self._step_socket = StepSocket(self._servicer, path, lambda: self.limits.transport[0])
        await self._step_socket.start()
        return True

    async def stop(self, grace: float = 2.0) -> None:
        """NOT_SERVING, end the active run, stop the server, close the participant."""
        served = self._server is not None  # else it never bound: its error says so, alone
        self._stopping = True
        self.health.reason = "the participant is shutting down"
        await self._set_health(health_pb2.HealthCheckResponse.NOT_SERVING)
        if self._servicer is not None:
            self._servicer.stopping = True
            try:
                await self._servicer.close_run("participant shutting down")
            except Exception:
                log.exception("terminate_on_shutdown_failed")
        if self._server is not None:
            await self._server.stop(grace)
        if self._step_socket is not None:
            await self._step_socket.stop()
        if self._health_server is not None:
            await self._health_server.stop(0)
        await self.participant.close()
        if served:
            log.info("participant_stopped", address=self.address)

    async def wait(self) -> None:
        if self._server is not None:
            await self._server.wait_for_termination()

    async def _report_health(self, reason: str | None) -> None:
        """The participant's word on whether it can take a run (``Participant.watch_health``)."""
        if self._stopping or (self._reported and reason == (self.health.reason or None)):
            return
        self._reported = True
        self.health.reason = reason or ""
        serving = health_pb2.HealthCheckResponse
        await self._set_health(serving.NOT_SERVING if reason else serving.SERVING)
        if reason:
            log.warning(
                "participant_not_serving", participant=self._name, address=self.address, why=reason
            )
        else:
            log.info("participant_serving", participant=self._name, address=self.address)

    async def _start_health_server(self, port: int) -> None:
        """The health service alone, plaintext: it tells whether this participant serves and
        nothing else, so probes that cannot do TLS (Kubernetes, Docker) need no secrets."""
        self._health_server = grpc.aio.server(options=ports.GRPC_SERVER_OPTIONS)
        health_pb2_grpc.add_HealthServicer_to_server(self.health, self._health_server)
        self.health_port = ports.add_grpc_port(
            self._health_server, self.host, port, None, "the health service (--health-port)"
        )
        await self._health_server.start()
        log.info("health_serving", address=f"grpc://{self.host}:{self.health_port}")

    async def _set_health(self, status: health_pb2.HealthCheckResponse.ServingStatus) -> None:
        await self.health.set("", status)
        await self.health.set(SERVICE_NAME, status)


def run(main: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run(main)`` on uvloop's event loop when uvloop is installed (a dependency of
    this package on Linux and macOS): a participant's step round trip measured 12-17 % faster
    with it (docs/performance.md); on the standard loop otherwise. The process keeps the
    memory it frees for its next frames (``coupler.heap``)."""
    from coupler.heap import keep_freed_memory

    keep_freed_memory()
    try:
        import uvloop
    except ImportError:
        return asyncio.run(main)
    with asyncio.Runner(loop_factory=uvloop.new_event_loop) as runner:
        return runner.run(main)


async def serve(
    participant: Participant,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    reflection: bool = False,
    security: ServerSecurity | None = None,
    on_started: Callable[[ParticipantServer], None] | None = None,
    max_message_bytes: int = MAX_MESSAGE_BYTES,
    unix_socket: Path | None = None,
) -> None:
    """Serve ``participant`` until SIGTERM or SIGINT, then shut down gracefully; on
    ``unix_socket`` (``unix:///PATH``, same host only) instead of ``host:port`` when given."""
    server = ParticipantServer(
        participant,
        host=host,
        port=port,
        reflection=reflection,
        security=security,
        max_message_bytes=max_message_bytes,
        unix_socket=unix_socket,
    )
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
