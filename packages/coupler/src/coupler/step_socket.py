"""The step socket (docs/protocol.md "Step socket"): a participant served on the unix socket
PATH also serves its step loop on PATH.steps, a plain unix socket (mode 0600) without gRPC.

A frame is a uint32 little-endian payload length, a uint8 kind, then the payload: kind 0 a
serialized DoStepRequest in and a DoStepResponse out, kind 1 the participant's last frame, a
StepSocketEnd with the loop's final status. The runtime (``coupler.server``) hands each request
to its ``StepLoop`` -- the same loop body StepStream runs, so every rule of a run holds alike --
and this module does the rest: frames read into buffers as they arrive, bounded (a frame over
the receive limit refused unread, a stalled frame ended, at most ``MAX_STEP_CONNECTIONS``).
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import os
import socket
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn, Protocol, cast

import grpc
import structlog
from google.protobuf.message import DecodeError

from coupler import ports, wire
from coupler.errors import ScenarioError

log = structlog.get_logger("coupler.server")


class StepLoop(Protocol):
    """What serves a step loop's requests (the runtime's servicer): one loop state per
    connection, each request stepped in order, the loop's end told."""

    def open_stream(self) -> Any:
        """A new loop's state (one per connection)."""
        ...

    async def stream_step(self, stream: Any, received: wire.StepRequest, context: Any) -> Any:
        """The answer to one request of the loop ``stream`` (``context``: a ``SocketContext``)."""
        ...

    def stream_ended(self, stream: Any, why: str) -> None:
        """The loop ``stream`` ended (finished, broken or cancelled)."""
        ...


_SERVING: set[asyncio.Task[None]] = set()
"""The connections' tasks (held so the loop does not drop them)."""

STEP_SOCKET_SUFFIX = ".steps"
"""A participant served on the unix socket PATH serves its step socket on PATH.steps."""
_HEADER = struct.Struct("<IB")
"""A frame's header: the payload's length (uint32, little-endian; the header not counted), then
its kind (uint8)."""
_STEP = 0
"""Kind of a frame carrying a serialized DoStepRequest (in) or DoStepResponse (out)."""
_END = 1
"""Kind of the participant's last frame: a serialized StepSocketEnd."""
_SMALL_FRAMES = 64 * 1024
"""A step socket connection's buffer of short frames [bytes]; a longer frame is read into a
buffer of its own."""
_FIRST_LONG = 4 * 1024 * 1024
"""The first buffer of a long frame [bytes] (the whole frame when it is shorter: a 1.44 MB
camera frame is read into one buffer of its size); a longer frame's buffer doubles as its bytes
arrive, so a header alone never makes the participant hold what it announces."""
MAX_STEP_CONNECTIONS = 4
"""Step socket connections served at once (one orchestrator steps a participant's run; the
rest are a reconnect's overlap); one more is answered RESOURCE_EXHAUSTED and closed."""
FRAME_STALL_S = 10.0
"""How long a frame begun on the step socket may wait for its next bytes [s]; then the
connection ends (DEADLINE_EXCEEDED), freeing what it held."""


class Aborted(Exception):
    """A step refused on the step socket: the end of its connection, with this status."""

    def __init__(self, code: grpc.StatusCode, message: str) -> None:
        super().__init__(message)
        self.code, self.message = code, message


class SocketContext:
    """What the step loop needs of a call's context, for a step socket connection: its peer,
    and ``abort``, which ends the connection with a status (``Aborted``)."""

    def __init__(self, peer: str) -> None:
        self._peer = peer

    def peer(self) -> str:
        return self._peer

    async def abort(self, code: grpc.StatusCode, details: str = "") -> NoReturn:
        raise Aborted(code, details)


class StepSocket:
    """The step socket: a plain unix socket (mode 0600) on which the participant serves its
    step loop without gRPC, one ``_StepConnection`` per orchestrator."""

    def __init__(self, loop: StepLoop, path: Path, limit: Callable[[], int]) -> None:
        self.loop, self.path, self.limit = loop, path, limit
        """``limit()``: the largest frame taken [bytes] (the server's gRPC receive limit)."""
        self.connections: set[_StepConnection] = set()
        self._server: asyncio.AbstractServer | None = None

    async def start(self) -> None:
        ports.clear_socket(self.path, "the step socket")
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            os.fchmod(sock.fileno(), 0o600)  # Linux makes the file with the socket's mode
            sock.bind(str(self.path))
            os.chmod(self.path, 0o600)
        except OSError as exc:
            sock.close()
            raise ScenarioError(f"cannot serve the step socket on {self.path} ({exc})") from None
        self._server = await asyncio.get_running_loop().create_unix_server(
            lambda: _StepConnection(self), sock=sock
        )

    async def stop(self) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        for connection in list(self.connections):
            connection.close()
        await server.wait_closed()
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()


class _StepConnection(asyncio.BufferedProtocol):
    """One orchestrator's step loop on the step socket: frames in, each request stepped by
    ``StepLoop.stream_step`` (StepStream's loop body) and answered in order; the end (the
    orchestrator's half-close, a refused step) is a StepSocketEnd frame, then the close.

    Frames are read by the event loop straight into buffers (``asyncio.BufferedProtocol``):
    short ones into a small buffer kept for the connection, from which each is copied once;
    a frame longer than that buffer into a buffer of its own size, which becomes the frame
    (a 1.44 MB camera frame: no copy in user space before ``wire.step_request`` cuts it out).
    """

    def __init__(self, socket: StepSocket) -> None:
        self._socket = socket
        self._small = bytearray(_SMALL_FRAMES)
        self._filled = 0
        """Bytes received into ``_small`` and not yet taken."""
        self._long: bytearray | None = None
        """The frame being read into a buffer of its own (None: none), its kind, its length
        and how many of its bytes have arrived."""
        self._long_kind = 0
        self._long_length = 0
        self._long_got = 0
        self._stall: asyncio.TimerHandle | None = None
        """Ends the connection when a begun frame waits too long for its bytes."""
        self._stalled = False
        self._frames: collections.deque[tuple[int, bytes | bytearray]] = collections.deque()
        self._oversize = 0
        """The length of a frame over the limit, refused unread (0: none)."""
        self._eof = False
        self._paused = False
        self._waiter: asyncio.Future[None] | None = None
        self._transport: asyncio.Transport | None = None
        self._task: asyncio.Task[None] | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.Transport, transport)  # uvloop's is not a subclass
        if len(self._socket.connections) >= MAX_STEP_CONNECTIONS:
            end = wire.step_socket_end(
                grpc.StatusCode.RESOURCE_EXHAUSTED.value[0],
                f"the step socket serves {MAX_STEP_CONNECTIONS} connections at once; this one "
                "is one too many (step a run over one connection)",
            )
            self._transport.writelines((_HEADER.pack(len(end), _END), end))
            self._transport.close()
            return
        self._socket.connections.add(self)
        peer = f"unix:{self._socket.path}"
        raw = transport.get_extra_info("socket")
        if raw is not None and hasattr(socket, "SO_PEERCRED"):
            with contextlib.suppress(OSError):
                credentials = raw.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, 12)
                peer += f" (pid {struct.unpack('3i', credentials)[0]})"
        self._task = asyncio.get_running_loop().create_task(self._serve(peer))
        _SERVING.add(self._task)
        self._task.add_done_callback(_SERVING.discard)

    def get_buffer(self, sizehint: int) -> memoryview:
        if self._long is not None:
            if self._long_got == len(self._long):  # full, the frame not: double it
                grown = bytearray(min(2 * len(self._long), self._long_length))
                grown[: self._long_got] = self._long
                self._long = grown
            return memoryview(self._long)[self._long_got :]
        if self._oversize or self._stalled:  # refused: what still arrives is dropped
            return memoryview(self._small)
        return memoryview(self._small)[self._filled :]

    def buffer_updated(self, nbytes: int) -> None:
        if self._oversize or self._stalled:
            return
        if self._long is not None:
            self._long_got += nbytes
            if self._long_got == self._long_length:
                self._frames.append((self._long_kind, self._long))
                self._long = None
        else:
            self._filled += nbytes
            self._split()
        self._watch_stall()
        if len(self._frames) > 1:
            self._pause()  # one request at a time: the orchestrator waits for each answer
        if self._frames or self._oversize:
            self._wake()

    def _split(self) -> None:
        """The whole frames in ``_small`` taken (one copy each); the rest moved to its start,
        or into a buffer of its own for a frame longer than ``_small``."""
        buffer, size, at = self._small, self._filled, 0
        while size - at >= _HEADER.size:
            length, kind = _HEADER.unpack_from(buffer, at)
            if length > self._socket.limit():
                self._oversize = length  # refused without reading it
                self._filled = 0
                self._pause()
                return
            start, end = at + _HEADER.size, at + _HEADER.size + length
            if end <= size:
                with memoryview(buffer) as view:
                    self._frames.append((kind, bytes(view[start:end])))
                at = end
                continue
            if _HEADER.size + length > len(buffer):  # the rest into a buffer of its own
                self._long = bytearray(min(length, max(_FIRST_LONG, size - start)))
                self._long_kind, self._long_length = kind, length
                self._long_got = size - start
                self._long[: self._long_got] = buffer[start:size]
                at = size
            break
        if at:
            rest = size - at
            buffer[:rest] = buffer[at:size]
            self._filled = rest

    def _watch_stall(self) -> None:
        """(Re)start the stall timer while a frame is begun, stop it when none is."""
        if self._stall is not None:
            self._stall.cancel()
            self._stall = None
        if (self._long is not None or self._filled) and not self._oversize:
            self._stall = asyncio.get_running_loop().call_later(FRAME_STALL_S, self._on_stall)

    def _on_stall(self) -> None:
        self._stall, self._stalled = None, True
        self._long = None  # what it held goes now, not when the connection closes
        self._pause()
        self._wake()

    def eof_received(self) -> bool:
        self._eof = True
        self._wake()
        return True  # keep writing: the answers, then the end

    def connection_lost(self, exc: Exception | None) -> None:
        self._eof = True
        self._long = None
        if self._stall is not None:
            self._stall.cancel()
            self._stall = None
        self._socket.connections.discard(self)
        self._wake()

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()

    def _pause(self) -> None:
        if not self._paused and self._transport is not None:
            self._paused = True
            self._transport.pause_reading()

    def _wake(self) -> None:
        waiter, self._waiter = self._waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    async def _next(self) -> tuple[int, bytes | bytearray] | None:
        """The next frame; None after the orchestrator's half-close (or a lost connection)."""
        while True:
            if self._frames:
                frame = self._frames.popleft()
                if self._paused and not self._frames and not self._oversize:
                    self._paused = False
                    assert self._transport is not None
                    self._transport.resume_reading()
                return frame
            if self._stalled:
                raise Aborted(
                    grpc.StatusCode.DEADLINE_EXCEEDED,
                    f"a frame begun on the step socket waited {FRAME_STALL_S:g} s for its next "
                    "bytes; the connection ends (send each frame whole)",
                )
            if self._oversize:
                raise Aborted(
                    grpc.StatusCode.RESOURCE_EXHAUSTED,
                    f"a frame of {self._oversize} bytes arrived on the step socket, over the "
                    f"participant's receive limit of {self._socket.limit()} bytes; raise the "
                    f'limit (docs/protocol.md "Message size") or send smaller values',
                )
            if self._eof:
                return None
            self._waiter = asyncio.get_running_loop().create_future()
            await self._waiter

    async def _serve(self, peer: str) -> None:
        loop, context = self._socket.loop, SocketContext(peer)
        stream = loop.open_stream()
        code, message = grpc.StatusCode.OK, ""
        try:
            while (frame := await self._next()) is not None:
                kind, payload = frame
                if kind != _STEP:
                    raise Aborted(
                        grpc.StatusCode.INVALID_ARGUMENT,
                        f"a frame of kind {kind} arrived on the step socket; the orchestrator "
                        f"sends kind {_STEP} (a DoStepRequest) only (docs/protocol.md)",
                    )
                try:
                    received = wire.step_request(payload)
                except DecodeError as exc:
                    raise Aborted(
                        grpc.StatusCode.INVALID_ARGUMENT,
                        f"a kind {_STEP} frame on the step socket is not a DoStepRequest ({exc})",
                    ) from None
                answer = await loop.stream_step(stream, received, context)
                pieces = wire.answer_pieces(answer)  # long Binary values as they are
                size = sum(map(len, pieces)) if len(pieces) > 1 else len(pieces[0])
                assert self._transport is not None
                self._transport.writelines((_HEADER.pack(size, _STEP), *pieces))
        except Aborted as exc:
            code, message = exc.code, exc.message
        except Exception as exc:  # the runtime's own failure: the loop ends, the server serves on
            log.exception("step_socket_failed", exc_info=exc)
            code, message = grpc.StatusCode.INTERNAL, f"{type(exc).__name__}: {exc}"
        finally:
            loop.stream_ended(stream, "its step socket connection ended without Terminate")
        transport = self._transport
        if transport is not None and not transport.is_closing():
            end = wire.step_socket_end(code.value[0], message)
            transport.writelines((_HEADER.pack(len(end), _END), end))
            transport.close()
