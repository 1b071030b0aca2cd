"""The native step channel: remote members' steps over C++ gRPC, on the master's thread.

A step through Python's ``grpc.aio`` crosses gRPC's poller thread and the event loop twice;
on a small machine that costs more than the participant's own work (docs/performance.md).
``native/step_streams.cc`` drives a member's StepStream from the calling thread instead,
through a completion queue of its own, and splits each step in two (``Participant.split``):
the master sends every due member its request, computes what it computes itself, then
receives the answers. Requests and answers are encoded and decoded here, by the same codec
as everywhere else, so the values are the same bytes either way.

The library is built on first use (a few seconds, once per machine) when the C++ gRPC tool
chain is installed (``scripts/install-grpc-dev.sh``); without it, or with
``--no-native-steps`` / ``COUPLER_NATIVE_STEPS=0``, remote steps go through ``grpc.aio`` with
the same meaning, the same errors and the same results.
"""

from __future__ import annotations

import ctypes
import os
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import grpc

from coupler import wire
from coupler.channels import RunSetup, Value
from coupler.client import RemoteParticipant, translate, uses_tls
from coupler.errors import ParticipantError, ParticipantTimeout
from coupler.participant import EndRun, Split, Values
from coupler.security import read_secret
from coupler.v1 import component_pb2 as pb
from coupler_orchestrator.export import (
    NativeLibrary,
    ToolchainMissing,
    cached_library,
    toolchain_problem,
)

SOURCE = Path(__file__).parent / "native" / "step_streams.cc"
ENVIRONMENT = "COUPLER_NATIVE_STEPS"
"""``0`` turns the native step channel off for every run of the process."""
_OK, _FAILED, _TIMEOUT = 0, 1, 2
_CODES = {code.value[0]: code for code in grpc.StatusCode}


def build(*, log_to_stderr: bool = True) -> Path:
    """The shared library, built on first use and cached under a key of its source, the
    compiler and gRPC's version; ToolchainMissing without the C++ gRPC tool chain."""
    if problem := toolchain_problem(("g++", "pkg-config"), ("grpc++",)):
        raise ToolchainMissing(f"cannot build the native step channel: {problem}")
    libraries = subprocess.run(
        ["pkg-config", "--cflags", "--libs", "grpc++"], capture_output=True, text=True, check=True
    ).stdout.split()
    return cached_library(
        SOURCE,
        compiler="g++",
        flags=["-shared", "-fPIC", "-O2", "-std=c++17", "-Wall", "-Wextra"],
        libraries=libraries,
        versions=[["g++", "--version"], ["pkg-config", "--modversion", "grpc++"]],
        prefix="libcoupler-steps",
        what="the native step channel",
        log_to_stderr=log_to_stderr,
    )


def wanted(asked: bool = True) -> bool:
    """Whether native stepping is asked for and not turned off by ``COUPLER_NATIVE_STEPS``."""
    return asked and os.environ.get(ENVIRONMENT, "1").strip().lower() not in ("0", "no", "false")


def _declare(lib: ctypes.CDLL) -> None:
    stream = ctypes.c_void_p
    lib.cs_open.restype = stream
    lib.cs_open.argtypes = [
        ctypes.c_char_p,
        ctypes.c_int,
        ctypes.c_char_p,
        ctypes.c_char_p,
        ctypes.c_char_p,
        ctypes.POINTER(ctypes.c_char_p),
        ctypes.c_int,
        ctypes.c_double,
    ]
    lib.cs_error.restype = ctypes.c_char_p
    lib.cs_error.argtypes = [stream]
    lib.cs_send.restype = ctypes.c_int
    lib.cs_send.argtypes = [stream, ctypes.c_char_p, ctypes.c_size_t]
    lib.cs_receive.restype = ctypes.c_int
    lib.cs_receive.argtypes = [
        stream,
        ctypes.c_double,
        ctypes.POINTER(ctypes.c_void_p),
        ctypes.POINTER(ctypes.c_size_t),
        ctypes.POINTER(ctypes.c_int),
    ]
    lib.cs_close.restype = None
    lib.cs_close.argtypes = [stream, ctypes.c_double]


library = NativeLibrary(build, _declare, "the native step channel")
"""``library()``: the loaded step channel, or None (why is said once)."""


def enabled(asked: bool = True) -> bool:
    """Whether runs step remote members natively: asked for, not turned off by the
    environment, and the library at hand."""
    return wanted(asked) and library() is not None


class NativeRemote(RemoteParticipant):
    """A remote participant whose steps travel over the native step channel (``split``);
    every other call, and the steps of a participant without StepStream, as
    ``RemoteParticipant``'s."""

    def __init__(self, address: str, **options: Any) -> None:
        super().__init__(address, streaming=False, **options)
        self._lib = library()
        self._native: int | None = None
        self._data = ctypes.c_void_p()
        self._size = ctypes.c_size_t()
        self._code = ctypes.c_int()

    async def initialize(self, setup: RunSetup) -> Values:
        outputs = await super().initialize(setup)
        if self._lib is not None and self.codec.description.capabilities.streaming:
            self._native = self._open()
        return outputs

    def _open(self) -> int:
        assert self._lib is not None
        security, tls = self.security, uses_tls(self.address)
        pems = [
            read_secret(path, what) if tls and path else b""
            for path, what in (
                (security.ca, "CA"),
                (security.key, "TLS key"),
                (security.cert, "TLS certificate"),
            )
        ]
        pairs = [text.encode() for pair in self._metadata for text in pair]
        metadata = (ctypes.c_char_p * max(1, len(pairs)))(*pairs)
        stream = self._lib.cs_open(
            self.target.encode(),
            int(tls),
            *pems,
            metadata,
            len(self._metadata),
            self.call_timeout,
        )
        error = self._lib.cs_error(stream).decode(errors="replace")
        if error:
            self._lib.cs_close(stream, 0.0)
            raise ParticipantError(
                f"{error} ({self.address})", participant=self.name, call="StepStream"
            )
        return int(stream)

    def split(self) -> Split | None:
        return self if self._native is not None else None

    def send(self, time: float, step: float, inputs: Mapping[str, Value]) -> None:
        """Put a step's request on its way; ``receive()`` takes the answer."""
        assert self._lib is not None and self._native is not None
        data = self.step_request(time, step, inputs).SerializeToString()
        if self._lib.cs_send(self._native, data, len(data)) != _OK:
            self.receive()  # the stream has ended: its status says why
            raise ParticipantError(
                "a step was sent before the previous answer was received",
                participant=self.name,
                call="DoStep",
            )

    def receive(self) -> Values:
        """The answer to the request sent; blocks up to the call deadline."""
        assert self._lib is not None and self._native is not None
        result = self._lib.cs_receive(
            self._native,
            self.call_timeout,
            ctypes.byref(self._data),
            ctypes.byref(self._size),
            ctypes.byref(self._code),
        )
        if result == _TIMEOUT:
            raise ParticipantTimeout(
                f"no answer within {self.call_timeout:g} s",
                participant=self.name,
                call="DoStep",
                status="DEADLINE_EXCEEDED",
            )
        if result != _OK:
            details = self._lib.cs_error(self._native).decode(errors="replace")
            raise translate(
                _CODES.get(self._code.value, grpc.StatusCode.UNKNOWN),
                details,
                participant=self.name,
                call="DoStep",
                address=self.address,
            )
        response = pb.DoStepResponse.FromString(ctypes.string_at(self._data, self._size.value))
        outputs = self._response("DoStep", lambda: wire.outputs_from_pb(response, self.codec))
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
