"""The native step channel: remote members' steps over C++ gRPC, on the master's thread.

A step through Python's ``grpc.aio`` crosses gRPC's poller thread and the event loop twice;
on a small machine that costs more than the participant's own work (docs/performance.md).
The native step channel (``coupler_native._step_streams``:
``packages/coupler-native/csrc/step_streams.cc``) drives a member's StepStream from the
calling thread instead, through a completion queue of its own, and splits each step in two
(``steppers.Split``): the master sends every due member its request, computes what it
computes itself, then receives the answers. Requests and answers are encoded and decoded
here, by the same codec as everywhere else, so the values are the same bytes either way.

It is compiled, with C++ gRPC bundled, when the coupler-native wheel is built (its functions
declared once, by ``csrc/step_streams.h``, which its cffi binding reads); without
coupler-native installed, or with ``--no-native-steps`` / ``COUPLER_NATIVE_STEPS=0``, remote
steps go through ``grpc.aio`` with the same meaning, the same errors and the same results.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import grpc

from coupler import wire
from coupler.channels import RunSetup, Value
from coupler.client import RemoteParticipant, translate, uses_tls
from coupler.errors import ParticipantError, ParticipantTimeout
from coupler.participant import EndRun, Values
from coupler.security import read_secret
from coupler_orchestrator.native import NativeModule

ENVIRONMENT = "COUPLER_NATIVE_STEPS"
"""``0`` turns the native step channel off for every run of the process."""
_CODES = {code.value[0]: code for code in grpc.StatusCode}


def wanted(asked: bool = True) -> bool:
    """Whether native stepping is asked for and not turned off by ``COUPLER_NATIVE_STEPS``."""
    return asked and os.environ.get(ENVIRONMENT, "1").strip().lower() not in ("0", "no", "false")


library = NativeModule("_step_streams", "the native step channel")
"""``library()``: the native step channel (``ffi``, ``lib``), or None (why is said once)."""


def enabled(asked: bool = True) -> bool:
    """Whether runs step remote members natively: asked for, not turned off by the
    environment, and the library at hand."""
    return wanted(asked) and library() is not None


def why_python(participant: object, asked: bool) -> str:
    """Why a remote participant (after Initialize) steps over ``grpc.aio``."""
    if not wanted(asked):
        return "native steps are off (--no-native-steps or COUPLER_NATIVE_STEPS=0)"
    if library() is None:
        return str(library.problem)
    if isinstance(participant, NativeRemote):
        return "the participant offers no StepStream"
    return "not a gRPC participant (its steps are Python calls)"


class NativeRemote(RemoteParticipant):
    """A remote participant whose steps travel over the native step channel (``split``);
    every other call, and the steps of a participant without StepStream, as
    ``RemoteParticipant``'s."""

    def __init__(self, address: str, **options: Any) -> None:
        super().__init__(address, streaming=False, **options)
        native = library()
        self._ffi: Any = None
        self._lib: Any = None
        self._native: Any = None
        """The open stream (a ``cs_stream *``)."""
        if native is not None:
            self._ffi, self._lib = native.ffi, native.lib
            self._data = native.ffi.new("const char **")
            self._size = native.ffi.new("size_t *")
            self._code = native.ffi.new("int *")
        self._sent: list[Any] = []
        """The pieces of the request under way (``send``)."""

    async def initialize(self, setup: RunSetup) -> Values:
        outputs = await super().initialize(setup)
        if self._lib is not None and self.codec.description.capabilities.streaming:
            self._native = self._open()
        return outputs

    def _open(self) -> Any:
        assert self._lib is not None and self._ffi is not None
        security, tls = self.security, uses_tls(self.address)
        pems = [
            read_secret(path, what) if tls and path else b""
            for path, what in (
                (security.ca, "CA"),
                (security.key, "TLS key"),
                (security.cert, "TLS certificate"),
            )
        ]
        pairs = [self._ffi.new("char[]", text.encode()) for pair in self._metadata for text in pair]
        metadata = self._ffi.new("char *[]", pairs or 1)
        stream = self._lib.cs_open(
            self.target.encode(),
            int(tls),
            *pems,
            metadata,
            len(self._metadata),
            self.call_timeout,
            self.transport_limit + wire.FRAMING_BYTES,
        )
        error = self._ffi.string(self._lib.cs_error(stream)).decode(errors="replace")
        if error:
            self._lib.cs_close(stream, 0.0)
            raise ParticipantError(
                f"{error} ({self.address})", participant=self.name, call="StepStream"
            )
        return stream

    def split(self) -> NativeRemote | None:
        return self if self._native is not None else None

    def send(self, time: float, step: float, inputs: Mapping[str, Value]) -> None:
        """Put a step's request on its way; ``receive()`` takes the answer."""
        assert self._lib is not None and self._native is not None
        pieces = self.step_request_pieces(time, step, inputs)
        # sent from these objects, not copied: kept until the next step or the stream's end
        self._sent = [self._ffi.from_buffer(piece) for piece in pieces]
        sizes = [len(piece) for piece in pieces]
        if self._lib.cs_send(self._native, self._sent, sizes, len(pieces)) != self._lib.CS_OK:
            self.receive()  # the stream has ended: its status says why
            raise ParticipantError(
                "a step was sent before the previous answer was received",
                participant=self.name,
                call="DoStep",
            )

    def receive(self) -> Values:
        """The answer to the request sent; blocks up to the call deadline."""
        assert self._lib is not None and self._ffi is not None and self._native is not None
        lib = self._lib
        result = lib.cs_receive(self._native, self.call_timeout, self._data, self._size, self._code)
        if result == lib.CS_TIMEOUT:
            raise ParticipantTimeout(
                f"no answer within {self.call_timeout:g} s",
                participant=self.name,
                call="DoStep",
                status="DEADLINE_EXCEEDED",
            )
        if result != lib.CS_OK:
            details = self._ffi.string(lib.cs_error(self._native)).decode(errors="replace")
            raise translate(
                _CODES.get(self._code[0], grpc.StatusCode.UNKNOWN),
                details,
                participant=self.name,
                call="DoStep",
                address=self.address,
            )
        response, large = wire.step_answer(self._ffi.buffer(self._data[0], self._size[0]))
        outputs = self._response(
            "DoStep", lambda: wire.outputs_from_pb(response, self.codec, large)
        )
        reason = wire.termination_requested(response)
        if reason is not None:
            raise EndRun(reason, outputs)
        return outputs

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        if self._native is None:
            return await super().do_step(time, step, inputs)
        self.send(time, step, inputs)
        return self.receive()

    async def terminate(self, reason: str = "") -> None:
        try:
            await super().terminate(reason)
        finally:
            self._close_native(timeout=1.0)

    async def close(self) -> None:
        self._close_native(timeout=0.0)
        await super().close()

    def _close_native(self, *, timeout: float) -> None:
        """Half-close the stream and wait briefly for its status: the run has ended either
        way, the stream's end only confirms it."""
        stream, self._native = self._native, None
        if stream is not None and self._lib is not None:
            self._lib.cs_close(stream, timeout)
        self._sent = []
