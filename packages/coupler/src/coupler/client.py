"""``RemoteParticipant``: a participant behind ``grpc://HOST:PORT`` (or ``grpcs://`` with TLS),
seen as a local one.

Its steps travel over ``grpc.aio`` (a StepStream where the participant offers one, else DoStep
calls) unless it is given a ``StepTransport`` (``RemoteParticipant(address, steps=...)``), as
an httpx client is given a transport: the orchestrator gives its native step channel that way.

gRPC errors are translated to Coupler's exception tree here, in ``translate``, and nowhere else (the
orchestrator's native step channel calls it too).
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace
from types import TracebackType
from typing import Any, TypeVar, cast
from urllib.parse import urlsplit

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from coupler import wire
from coupler.channels import Description, RunSetup, Value
from coupler.errors import (
    ChannelValueError,
    MessageTooLarge,
    ParticipantError,
    ParticipantTimeout,
    ParticipantUnavailable,
    ScenarioError,
    ValueTooLarge,
    answered_unasked,
    foreign,
)
from coupler.participant import HEALTH_REASON, EndRun, Participant, Values
from coupler.security import ClientSecurity
from coupler.v1 import component_pb2_grpc as pb_grpc
from coupler.values import MAX_MESSAGE_BYTES, ValuePolicy

T = TypeVar("T")
_UNAVAILABLE = {grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.CANCELLED}


SCHEMES = ("grpc", "grpcs")


def parse_address(address: str) -> str:
    """``grpc://host:port``, ``grpcs://host:port``, ``unix:///path`` (or bare ``host:port``) as
    the target string grpc wants; ScenarioError for anything else (a path after the port, a
    query, a fragment, user information: none of them means anything to gRPC)."""
    if address.startswith("unix://"):
        path = address.removeprefix("unix://")
        if not path.startswith("/") or any(c in path for c in "?#\x00"):
            raise ScenarioError(
                f"'{address}' is not a unix socket address; write unix:///ABSOLUTE/PATH"
            )
        return f"unix:{path}"
    try:
        parts = urlsplit(address if "://" in address else f"grpc://{address}")
        port = parts.port
    except ValueError:
        port = None
    extra = parts.path not in ("", "/") or parts.query or parts.fragment or "@" in parts.netloc
    if parts.scheme not in SCHEMES or not parts.hostname or port is None or extra:
        raise ScenarioError(
            f"'{address}' is not a participant address; write grpc://HOST:PORT (or grpcs:// "
            f"for TLS), e.g. grpc://127.0.0.1:50051"
        )
    host = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"{host}:{port}"


def uses_tls(address: str) -> bool:
    """Whether ``address`` asks for TLS (``grpcs://``)."""
    return address.startswith("grpcs://")


class StepTransport(ABC):
    """How a ``RemoteParticipant``'s steps travel once its run is initialized, when not over
    its own ``grpc.aio`` channel. One transport serves one participant."""

    @abstractmethod
    def start(self, participant: RemoteParticipant) -> bool:
        """After Initialize: take this run's steps (True), or leave them to the participant's
        ``grpc.aio`` calls (False, e.g. when the participant offers no StepStream). Raises
        ``ParticipantError`` when it should take them and cannot."""

    @abstractmethod
    async def step(self, request: wire.DoStepRequest) -> wire.DoStepResponse:
        """The participant's answer to one step's request; Coupler's errors (``translate``)."""

    @abstractmethod
    def close(self, *, timeout: float) -> None:
        """End this run's steps: after Terminate, waiting up to ``timeout`` seconds for the
        end's status; at once (``timeout`` 0) when the participant is closed."""

    async def end(self) -> None:
        """After Terminate: this run's steps ended, their end's status waited for a while."""
        self.close(timeout=1.0)

    def split(self) -> Any | None:
        """This run's steps in two halves on the caller's thread (an object with ``send`` and
        ``receive``), when the transport carries them and can; None: through ``step``."""
        return None


class _Unary(StepTransport):
    """Steps as DoStep calls on the participant's ``grpc.aio`` channel."""

    def __init__(self, participant: RemoteParticipant) -> None:
        self._participant = participant

    def start(self, participant: RemoteParticipant) -> bool:
        return True

    async def step(self, request: wire.DoStepRequest) -> wire.DoStepResponse:
        p = self._participant
        call = p._stubbed().DoStep(request, timeout=p.call_timeout, metadata=p.metadata)
        response: wire.DoStepResponse = await p._call("DoStep", call)
        return response

    def close(self, *, timeout: float) -> None:
        pass


class _Streamed(StepTransport):
    """Steps over one StepStream on the participant's ``grpc.aio`` channel: a request
    written, its answer read, each within the call deadline."""

    def __init__(self, participant: RemoteParticipant) -> None:
        self._participant = participant
        self._stream: grpc.aio.StreamStreamCall = participant._stubbed().StepStream(
            metadata=participant.metadata
        )

    def start(self, participant: RemoteParticipant) -> bool:
        return True

    async def step(self, request: wire.DoStepRequest) -> wire.DoStepResponse:
        response: wire.DoStepResponse = await self._participant._call(
            "DoStep", self._exchange(request)
        )
        return response

    async def _exchange(self, request: wire.DoStepRequest) -> wire.DoStepResponse:
        p, stream = self._participant, self._stream
        try:
            await stream.write(request)
            async with asyncio.timeout(p.call_timeout):  # no task per step (wait_for's)
                response = await stream.read()
        except asyncio.InvalidStateError:  # the stream ended before this step was written
            response = grpc.aio.EOF
        if response is grpc.aio.EOF:  # the server closed the stream: its status says why
            code = await stream.code()
            details = await stream.details()
            raise translate(code, details, participant=p.name, call="DoStep", address=p.address)
        return cast(wire.DoStepResponse, response)

    async def end(self) -> None:
        """Half-close the run's step stream and wait for its status: the run has ended either
        way, the stream's end only confirms it -- unless answers come that no request asked
        for (ABORTED: the participant answered a request twice)."""
        p, stream = self._participant, self._stream
        unasked = 0
        with contextlib.suppress(grpc.aio.AioRpcError, TimeoutError, asyncio.InvalidStateError):
            await stream.done_writing()
            async with asyncio.timeout(p.call_timeout):
                while await stream.read() is not grpc.aio.EOF:
                    unasked += 1
                await stream.code()
        if unasked:
            raise ParticipantError(
                answered_unasked(unasked), participant=p.name, call="Terminate", status="ABORTED"
            )

    def close(self, *, timeout: float) -> None:
        self._stream.cancel()


class RemoteParticipant(Participant):
    """A participant reached over gRPC.

    ``open()`` waits until the participant's health is SERVING (within ``connect_timeout``) and
    describes it; every call then has a deadline of ``call_timeout`` seconds. With
    ``streaming`` (and a participant that supports it) steps travel over one StepStream;
    given ``steps`` (a ``StepTransport``), over that transport when it takes them.
    The values of one message (Binary and String together) may have ``max_message_bytes``, or
    what the participant's channels declare (``Channel.max_bytes``) when that is less; one over
    it, either way, fails naming its channel (``MessageTooLarge``), and so does a value over
    its channel's declared maximum (``ValueTooLarge``). The gRPC channel's limits follow
    (``wire.client_limits``): once described, the participant is reached over a channel made
    with them.
    """

    def __init__(
        self,
        address: str,
        *,
        name: str | None = None,
        connect_timeout: float = 10.0,
        call_timeout: float = 30.0,
        streaming: bool = True,
        security: ClientSecurity | None = None,
        on_waiting: Callable[[str], None] | None = None,
        max_message_bytes: int = MAX_MESSAGE_BYTES,
        steps: StepTransport | None = None,
    ) -> None:
        self.address = address
        self.steps = steps
        """The transport given for the steps (None: ``grpc.aio``)."""
        self._transport: StepTransport | None = None
        """How this run's steps travel, chosen once at Initialize: ``steps`` when it takes
        them, else a StepStream where the participant offers one and ``streaming``, else
        DoStep calls."""
        self.max_message_bytes = max_message_bytes
        self.limits = wire.MessageLimits(*[max(max_message_bytes, MAX_MESSAGE_BYTES)] * 2)
        """What the gRPC channel lets through (``wire.client_limits`` once described; before,
        at least what a participant's server sends by default)."""
        self.target = parse_address(address)
        self.security = security or ClientSecurity()
        self._metadata = self.security.metadata()
        self.on_waiting = on_waiting
        self.name = name or address
        self.connect_timeout = connect_timeout
        self.call_timeout = call_timeout
        self.streaming = streaming
        self._channel: grpc.aio.Channel | None = None
        self._stub: pb_grpc.GRPCComponentServiceStub | None = None
        self._codec: wire.Codec | None = None
        self._run = wire.RunKey()
        """The run's id and secret, carried by every call after Initialize."""
        self._requests: wire.StepRequests | None = None
        """The run's step requests, one prepared message (``step_request_pieces``)."""
        self.reported: wire.StepCost = (None, None)
        """What the last step's answer said the step cost the participant, and how much of it
        it waited for an outside program (``wire.step_cost``)."""

    @property
    def metadata(self) -> tuple[tuple[str, str], ...]:
        """What every call carries (the bearer token, when there is one)."""
        return self._metadata

    async def __aenter__(self) -> RemoteParticipant:
        await self.open()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def open(self) -> None:
        if self._codec is not None:
            return
        self._ensure_channel()
        await self.wait_until_serving()
        response = await self._call(
            "Describe",
            self._stubbed().Describe(
                wire.DescribeRequest(), timeout=self.call_timeout, metadata=self._metadata
            ),
        )
        description = wire.description_from_pb(response)
        policy = ValuePolicy(max_message_bytes=self.max_message_bytes, cap_declared=True)
        self._codec = wire.Codec(description, policy)
        limits = wire.client_limits(description, self.max_message_bytes)
        if limits != self.limits:  # gRPC fixes a channel's limits when it is made
            self.limits = limits
            channel, self._channel = self._channel, None
            if channel is not None:
                await channel.close()
            self._ensure_channel()

    async def wait_until_serving(self) -> None:
        """Poll the health service until SERVING; ParticipantUnavailable after the deadline, or
        at once when TLS cannot work (a certificate problem does not go away by waiting).

        ``on_waiting(reason)`` is called once, as soon as the first check is not SERVING.
        """
        assert self._channel is not None
        health_stub = health_pb2_grpc.HealthStub(self._channel)
        deadline = time.monotonic() + self.connect_timeout
        delay, last, told = 0.05, "no answer", False
        while True:
            remaining = deadline - time.monotonic()
            try:
                why = await _not_serving(
                    health_stub, deadline_s=max(0.1, min(2.0, remaining)), metadata=self._metadata
                )
                if why is None:
                    return
                last = why
            except grpc.aio.AioRpcError as exc:
                tls = tls_problem(exc.details() or "", self.address, self.security)
                if tls is not None:
                    raise ParticipantUnavailable(
                        f"{tls} ({self.address})",
                        participant=self.name,
                        call="connect",
                        status="UNAVAILABLE",
                    ) from exc
                last = _why_unreachable(exc)
            if not told and self.on_waiting is not None:
                told = True
                self.on_waiting(last)
            if time.monotonic() + delay > deadline:
                raise ParticipantUnavailable(
                    f"not SERVING at {self.address} within {self.connect_timeout:g} s ({last}); "
                    f"is the participant running and listening on that address?",
                    participant=self.name,
                    call="connect",
                    status="UNAVAILABLE",
                )
            await asyncio.sleep(delay)
            delay = min(delay * 2, 0.5)

    async def wait_until_serving_once(self) -> None:
        """One health check; ParticipantUnavailable unless SERVING."""
        self._ensure_channel()
        assert self._channel is not None
        try:
            why = await _not_serving(
                health_pb2_grpc.HealthStub(self._channel), deadline_s=self.connect_timeout
            )
        except grpc.aio.AioRpcError as exc:
            raise translate(
                exc.code(),
                exc.details(),
                participant=self.name,
                call="health",
                address=self.address,
            ) from exc
        if why is not None:
            raise ParticipantUnavailable(
                why, participant=self.name, call="health", status="UNAVAILABLE"
            )

    def _ensure_channel(self) -> None:
        if self._channel is None:
            options = self.limits.options()
            if uses_tls(self.address):
                credentials = self.security.channel_credentials()
                self._channel = grpc.aio.secure_channel(self.target, credentials, options)
            else:
                self._channel = grpc.aio.insecure_channel(self.target, options)
            self._stub = pb_grpc.GRPCComponentServiceStub(self._channel)

    @property
    def codec(self) -> wire.Codec:
        if self._codec is None:
            raise ParticipantError(
                "not connected; call open() first", participant=self.name, call="describe"
            )
        return self._codec

    async def describe(self) -> Description:
        await self.open()
        return self.codec.description

    async def initialize(self, setup: RunSetup) -> Values:
        if not setup.run_secret:  # a caller that brings none (not the orchestrator) gets one
            setup = replace(setup, run_secret=secrets.token_bytes(wire.SECRET_BYTES))
        request = self._request("Initialize", lambda: wire.initialize_to_pb(setup, self.codec))
        # Terminate names the run even when Initialize's answer is bad
        self._run = wire.RunKey(setup.run_id, setup.run_secret)
        self._requests = None  # the run's requests are prepared with its id and secret
        response = await self._call(
            "Initialize",
            self._stubbed().Initialize(request, timeout=self.call_timeout, metadata=self._metadata),
        )
        outputs = self._response("Initialize", lambda: wire.outputs_from_pb(response, self.codec))
        if self.steps is not None and self.steps.start(self):
            self._transport = self.steps
        elif self.streaming and self.codec.description.capabilities.streaming:
            self._transport = _Streamed(self)
        else:
            self._transport = _Unary(self)
        return outputs

    def step_request(
        self, time: float, step: float, inputs: Mapping[str, Value]
    ) -> wire.DoStepRequest:
        """The DoStep request of the run (its id and secret), inputs checked."""
        return self._request(
            "DoStep", lambda: wire.step_to_pb(self._run, time, step, inputs, self.codec)
        )

    def step_request_pieces(
        self, time: float, step: float, inputs: Mapping[str, Value]
    ) -> list[bytes]:
        """``step_request`` serialized as pieces whose concatenation is the message, each long
        Binary input a piece of its own (``wire.step_pieces``): for a transport that sends from
        them without copying."""
        requests = self._requests
        if requests is None:
            requests = self._requests = wire.StepRequests(self.codec, self._run)
        return self._request("DoStep", lambda: requests.pieces(time, step, inputs))

    def step_outputs(
        self, response: wire.DoStepResponse, large: Iterable[tuple[str, bytes]] = ()
    ) -> Values:
        """A DoStep answer's outputs, checked against the description, with the long Binary
        outputs ``wire.step_answer`` cut out of it (``large``); ``EndRun`` (with them) when the
        participant asks to end the run."""
        outputs = self._response(
            "DoStep", lambda: wire.outputs_from_pb(response, self.codec, large)
        )
        self.reported = wire.step_cost(response)
        reason = wire.termination_requested(response)
        if reason is not None:
            raise EndRun(reason, outputs)
        return outputs

    def split(self) -> Any | None:
        """Its steps in two halves on the caller's thread, when its transport can (the
        orchestrator's native step channel: ``StepTransport.split``); None: ``do_step``."""
        return self.steps.split() if self.steps is not None else None

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return self.step_outputs(await self._steps().step(self.step_request(time, step, inputs)))

    def _steps(self) -> StepTransport:
        """The run's transport; outside a run, DoStep calls (the participant says why not)."""
        return self._transport or _Unary(self)

    async def terminate(self, reason: str = "") -> None:
        """Terminate the run (named by its id), then end its steps' transport."""
        transport, self._transport = self._transport, None
        try:
            await self._call(
                "Terminate",
                self._stubbed().Terminate(
                    wire.terminate_to_pb(self._run, reason),
                    timeout=self.call_timeout,
                    metadata=self._metadata,
                ),
            )
        finally:
            if transport is not None:
                await transport.end()

    async def close(self) -> None:
        transport, self._transport = self._transport, None
        if transport is not None:
            transport.close(timeout=0.0)
        if self._channel is not None:
            await self._channel.close()
        self._channel = None
        self._stub = None
        self._codec = None

    def _stubbed(self) -> pb_grpc.GRPCComponentServiceStub:
        if self._stub is None:
            raise ParticipantError(
                "not connected; call open() first", participant=self.name, call="call"
            )
        return self._stub

    def _request(self, call: str, build: Any) -> Any:
        try:
            return build()
        except (MessageTooLarge, ValueTooLarge) as exc:
            raise ParticipantError(
                exc.naming(self.name), participant=self.name, call=call, status="RESOURCE_EXHAUSTED"
            ) from exc
        except ChannelValueError as exc:
            raise ParticipantError(
                str(exc), participant=self.name, call=call, status="INVALID_ARGUMENT"
            ) from exc

    def _response(self, call: str, read: Any) -> Values:
        try:
            outputs: Values = read()
        except (MessageTooLarge, ValueTooLarge) as exc:
            raise ParticipantError(
                exc.naming(self.name), participant=self.name, call=call, status="RESOURCE_EXHAUSTED"
            ) from exc
        except ChannelValueError as exc:
            raise ParticipantError(
                f"answered outside its description: {exc}", participant=self.name, call=call
            ) from exc
        return outputs

    async def _call(self, call: str, pending: Any) -> Any:
        try:
            return await pending
        except grpc.aio.AioRpcError as exc:
            raise translate(
                exc.code(), exc.details(), participant=self.name, call=call, address=self.address
            ) from exc
        except TimeoutError as exc:
            raise ParticipantTimeout(
                f"no answer within {self.call_timeout:g} s",
                participant=self.name,
                call=call,
                status="DEADLINE_EXCEEDED",
            ) from exc


def translate(
    code: grpc.StatusCode, details: str | None, *, participant: str, call: str, address: str
) -> ParticipantError:
    """The one place gRPC errors become Coupler errors (the participant's words escaped:
    ``errors.foreign``)."""
    details = foreign(details) if details else code.name
    if code in _UNAVAILABLE:
        details = tls_problem(details, address, None) or details
        return ParticipantUnavailable(
            f"{details} ({address})", participant=participant, call=call, status=code.name
        )
    if code is grpc.StatusCode.DEADLINE_EXCEEDED:
        return ParticipantTimeout(details, participant=participant, call=call, status=code.name)
    if code is grpc.StatusCode.RESOURCE_EXHAUSTED and "larger than max" in details:
        details += (
            ": a message over the transport's limit (its values' limit plus framing); raise "
            "the message limit on both sides (coupler run --max-message-size MiB; a "
            'participant\'s server: max_message_bytes, docs/protocol.md "Message size")'
        )
    return ParticipantError(details, participant=participant, call=call, status=code.name)


async def _not_serving(
    stub: health_pb2_grpc.HealthStub,
    *,
    deadline_s: float,
    metadata: tuple[tuple[str, str], ...] | None = None,
) -> str | None:
    """None when the health service says SERVING, else what it says, with the participant's
    reason (trailing metadata ``coupler-health-reason``) when it gives one."""
    request = health_pb2.HealthCheckRequest(service="")
    call = stub.Check(request, timeout=deadline_s, metadata=metadata)
    reply = await call
    if reply.status == health_pb2.HealthCheckResponse.SERVING:
        return None
    status = health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status)
    trailing = await call.trailing_metadata()
    reasons = [str(v) for k, v in trailing or () if k == HEALTH_REASON]
    return f"health is {status}" + "".join(f": {r}" for r in reasons[:1])


def _why_unreachable(exc: grpc.aio.AioRpcError) -> str:
    """A short reason why a health check did not answer, e.g. "connection refused"."""
    details = exc.details() or ""
    if "Connection refused" in details or "connection refused" in details:
        return "connection refused: nothing listens on that port yet"
    if exc.code() is grpc.StatusCode.DEADLINE_EXCEEDED:
        return "no answer within the check's deadline"
    return f"{exc.code().name}: {details}"


_UNTRUSTED = ("CERTIFICATE_VERIFY_FAILED", "BAD_SIGNATURE", "unable to get local issuer")


def tls_problem(details: str, address: str, security: ClientSecurity | None) -> str | None:
    """What a failed connection says about TLS, in words; None when it is not about TLS."""
    tls = uses_tls(address)
    if "WRONG_VERSION_NUMBER" in details:
        return (
            "TLS handshake failed: the participant does not speak TLS; write grpc:// or give "
            "the participant a certificate"
        )
    if any(mark in details for mark in _UNTRUSTED):
        return (
            "TLS: the participant's certificate is not trusted by the CA given "
            "(--tls-ca / COUPLER_TLS_CA), or it was signed by another CA"
        )
    if "Peer name" in details or ("hostname" in details.lower() and "match" in details):
        return (
            "TLS: the participant's certificate is not valid for the host name in the address; "
            "use a name its certificate names"
        )
    if "Socket closed" in details and security is not None:
        if not tls:
            return (
                "the participant closed the connection at once: if it serves TLS, write "
                "grpcs:// in its address"
            )
        if security.cert is None:
            return (
                "the participant closed the TLS connection during the handshake: it requires a "
                "client certificate (mutual TLS) and none was given (--tls-cert and --tls-key "
                "/ COUPLER_TLS_CERT and COUPLER_TLS_KEY)"
            )
        return (
            "the participant refused the TLS handshake: it does not accept the client "
            "certificate (is it signed by the client CA the participant trusts?)"
        )
    if "handshake" in details.lower() and tls:
        return f"TLS handshake failed: {details}"
    return None
