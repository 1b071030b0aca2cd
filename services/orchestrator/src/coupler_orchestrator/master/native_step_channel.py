"""The native step channel: remote members' steps over C++ gRPC, on the master's thread.

A step through Python's ``grpc.aio`` crosses gRPC's poller thread and the event loop twice;
on a small machine that costs more than the participant's own work (docs/performance.md).
The native step channel (``coupler_native._step_streams``:
``packages/coupler-native/csrc/step_streams.cc``) drives a member's StepStream from the
calling thread instead, through a completion queue of its own, and splits each step in two
(``steppers.Split``): the master sends every due member its request, computes what it
computes itself, then receives the answers. Requests and answers are encoded and decoded
here, by the same codec as everywhere else, so the values are the same bytes either way; an
answer in the plain form every participant writes (outputs and the step's cost only, each
binding its channel and one value of its channel's type) is read from its bytes in C
(``coupler_native._answers``), into the same values as its Python twin ``ProtobufAnswers``
reads (one ``native.AnswerReader``), and any other through protobuf and the codec, which say
what is wrong.

It is compiled, with C++ gRPC bundled, when the coupler-native wheel is built (its functions
declared once, by ``csrc/step_streams.h``; ``coupler_native._step_streams.Stream`` drives them,
without the GIL while it waits); without
coupler-native installed, or with ``--no-native-steps`` / ``COUPLER_NATIVE_STEPS=0``, remote
steps go through ``grpc.aio`` with the same meaning, the same errors and the same results.

A member reached over ``unix://`` whose Describe offers a step socket
(``Capabilities.step_socket``, docs/protocol.md "Step socket") is stepped over that socket
instead, by the same native calls (the target ``steps:PATH``): the same requests and answers,
framed on a plain unix socket without gRPC's per-message work. ``--no-step-socket`` /
``COUPLER_STEP_SOCKET=0`` keep its StepStream; a step socket that cannot be opened leaves the
member on its StepStream too (equivalent), with a warning in the run's log naming the member,
the path and why, which summary.json's step path repeats.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import grpc
import structlog
from google.protobuf.message import DecodeError

from coupler import wire
from coupler.channels import Value
from coupler.client import RemoteParticipant, StepTransport, translate, uses_tls
from coupler.errors import ParticipantError, ParticipantTimeout, answered_unasked, foreign
from coupler.participant import Values
from coupler.security import read_secret
from coupler.v1 import component_pb2 as pb
from coupler_orchestrator.native import AnswerReader, step_streams
from coupler_orchestrator.native import answers as answers

_CODES = {code.value[0]: code for code in grpc.StatusCode}
log = structlog.get_logger("coupler.master")

STREAM = ("native step channel", "its StepStream over C++ gRPC")
"""How summary.json names a member stepped over its StepStream, and why."""

library = step_streams
"""``library()``: the native step channel (``coupler_native._step_streams``), or None (why is
said once)."""


def enabled(asked: bool = True) -> bool:
    """Whether runs step remote members natively: asked for (``RunOptions.native_steps``,
    the environment applied by ``RunOptions.switched``) and the library at hand."""
    return asked and library() is not None


def why_python(participant: object, asked: bool) -> str:
    """Why a remote participant (after Initialize) steps over ``grpc.aio``."""
    if not asked:
        return "native steps are off (--no-native-steps or COUPLER_NATIVE_STEPS=0)"
    if library() is None:
        return str(library.problem)
    if callable(getattr(participant, "split", None)):  # given this channel, which it did not take
        return "the participant offers no StepStream"
    return "not a gRPC participant (its steps are Python calls)"


class NativeSteps(StepTransport):
    """A remote participant's steps over the native step channel, given to it as its
    ``StepTransport`` (``transport``); ``split`` gives the master the two halves of a step.
    Taken when the participant offers a StepStream; without one its steps stay DoStep calls.
    With ``step_socket`` (``RunOptions.step_socket``), over the participant's step socket where it
    offers one and is reached over a unix socket."""

    def __init__(self, step_socket: bool = True) -> None:
        self._step_socket = step_socket
        self.described = STREAM
        """How summary.json names the way this member steps, and why (``steppers.Split``)."""
        native = library()
        assert native is not None, "NativeSteps without the native step channel"
        self._library = native
        self._remote: RemoteParticipant | None = None
        self._native: Any = None
        """The open stream (a ``coupler_native._step_streams.Stream``)."""
        self._reader: AnswerReader | None = None
        """Reads an answer's outputs and cost when it only answers the step (in C where
        coupler-native's ``_answers`` is at hand, else ``ProtobufAnswers``)."""
        self.reported: wire.StepCost = (None, None)
        """What the last answer said its step cost the participant (``wire.step_cost``)."""

    def start(self, participant: RemoteParticipant) -> bool:
        capabilities = participant.codec.description.capabilities
        if not capabilities.streaming and not capabilities.step_socket:
            return False
        self._remote = participant
        self._native = self._open(participant)
        codec, read = participant.codec, answers()
        self._reader = (
            read.AnswerRead(codec.answer_fields(), codec.policy.max_message_bytes)
            if read is not None
            else ProtobufAnswers(codec)
        )
        return True

    def _open(self, remote: RemoteParticipant) -> Any:
        offered = remote.codec.description.capabilities.step_socket
        self.described = STREAM
        if offered and remote.address.startswith("unix://") and self._step_socket:
            stream = self._open_socket(remote, offered)
            if stream is not None:
                return stream
        security, tls = remote.security, uses_tls(remote.address)
        pems = [
            read_secret(path, what) if tls and path else b""
            for path, what in (
                (security.ca, "CA"),
                (security.key, "TLS key"),
                (security.cert, "TLS certificate"),
            )
        ]
        stream = self._library.Stream(
            remote.target.encode(),
            tls,
            *pems,
            remote.metadata,
            remote.call_timeout,
            *remote.limits.transport,  # received, sent: from the participant's declarations
        )
        error = stream.error
        if error:
            stream.close(0.0)
            raise ParticipantError(
                f"{error} ({remote.address})", participant=remote.name, call="StepStream"
            )
        return stream

    def _open_socket(self, remote: RemoteParticipant, path: str) -> Any:
        """The participant's step socket opened, or None (said in the run's log): its
        StepStream does the same."""
        stream = self._library.Stream(
            f"steps:{path}".encode(), False, b"", b"", b"", (), remote.call_timeout,
            *remote.limits.transport,
        )  # fmt: skip
        error = stream.error
        if not error:
            self.described = ("native step socket", f"its step socket {path}, without gRPC")
            return stream
        stream.close(0.0)
        self.described = (STREAM[0], f"{STREAM[1]}: its step socket did not open ({error})")
        log.warning(
            "step_socket_unavailable",
            participant=remote.name,
            path=path,
            error=error,
            instead="its StepStream",
        )
        return None

    def split(self) -> NativeSteps | None:
        """The two halves of a step (``steppers.Split``) while this transport carries a run."""
        return self if self._native is not None else None

    def send(self, time: float, step: float, inputs: Mapping[str, Value]) -> None:
        """Put a step's request on its way; ``receive()`` takes the answer."""
        assert self._remote is not None and self._native is not None
        self._send(self._remote.step_request_pieces(time, step, inputs))

    def _send(self, pieces: list[bytes]) -> None:
        """Send a request given as pieces whose concatenation is the message (sent from these
        objects, not copied: the stream holds them until the next step or its end)."""
        assert self._remote is not None
        if not self._native.send(pieces):
            self._answer()  # the stream has ended: its status says why
            raise ParticipantError(
                "a step was sent before the previous answer was received",
                participant=self._remote.name,
                call="DoStep",
            )

    def receive(self) -> Values:
        """The answer to the request sent; blocks up to the call deadline."""
        assert self._remote is not None
        data = self._answered()
        assert self._reader is not None
        found = self._reader.read(data)
        if found is not None:  # the answer of every step
            outputs, seconds, waited = found
            self.reported = wire.cost_of(seconds, waited)
            return outputs
        try:  # an end of the run asked for, or an answer that is refused: said here
            response, large = wire.step_answer(data)
        except DecodeError as exc:
            raise self._not_an_answer(exc) from None
        self.reported = wire.step_cost(response)
        return self._remote.step_outputs(response, large)

    def _answer(self) -> pb.DoStepResponse:
        try:
            return pb.DoStepResponse.FromString(self._answered())
        except DecodeError as exc:
            raise self._not_an_answer(exc) from None

    def _not_an_answer(self, exc: DecodeError) -> ParticipantError:
        assert self._remote is not None
        return ParticipantError(
            f"its answer is not a DoStepResponse ({foreign(str(exc))}); the participant does "
            "not speak the protocol (docs/protocol.md)",
            participant=self._remote.name,
            call="DoStep",
            status="INTERNAL",
        )

    def _answered(self) -> memoryview:
        """The serialized answer to the request sent (valid until the next receive)."""
        assert self._remote is not None and self._native is not None
        remote, stream = self._remote, self._native
        data: memoryview | None = stream.receive(remote.call_timeout)
        if data is not None:
            return data
        result, code = stream.failure
        if result == self._library.CS_TIMEOUT:
            raise ParticipantTimeout(
                f"no answer within {remote.call_timeout:g} s",
                participant=remote.name,
                call="DoStep",
                status="DEADLINE_EXCEEDED",
            )
        raise translate(
            _CODES.get(code, grpc.StatusCode.UNKNOWN),
            stream.error,
            participant=remote.name,
            call="DoStep",
            address=remote.address,
        )

    async def step(self, request: pb.DoStepRequest) -> pb.DoStepResponse:
        self._send([request.SerializeToString()])
        return self._answer()

    def close(self, *, timeout: float) -> None:
        """Half-close the stream and wait briefly for its status: the run has ended either
        way, the stream's end only confirms it -- unless answers came that no request asked
        for (ABORTED: the participant answered a request twice)."""
        stream, self._native = self._native, None
        if stream is not None and (unasked := stream.close(timeout)) > 0:
            assert self._remote is not None
            raise ParticipantError(
                answered_unasked(unasked),
                participant=self._remote.name,
                call="Terminate",
                status="ABORTED",
            )


class ProtobufAnswers:
    """``AnswerReader`` in Python: an answer read by protobuf and the codec (the twin of
    ``coupler_native._answers.AnswerRead``; the same values)."""

    def __init__(self, codec: wire.Codec) -> None:
        self._codec = codec

    def read(self, data: Any, /) -> tuple[Values, float, float] | None:
        try:
            response, large = wire.step_answer(data)
            if response.terminate:
                return None
            outputs = wire.outputs_from_pb(response, self._codec, large)
        except Exception:  # DecodeError, the codec's refusals: the caller reads it to say so
            return None
        return outputs, response.step_seconds, response.waited_seconds


def transport(asked: bool = True, step_socket: bool = True) -> Callable[[], StepTransport | None]:
    """What gives each remote participant of a run its step transport: the native step
    channel where it is wanted and at hand (over the step socket where one is offered and
    ``step_socket``), else nothing (``grpc.aio``)."""
    if not enabled(asked):
        return lambda: None
    return lambda: NativeSteps(step_socket)
