"""The step socket as a client written from docs/protocol.md ("Step socket") alone sees it:

    python -m coupler.examples gain --socket DIR/gain.sock        (a subprocess)
        Describe (gRPC)   -> capabilities.step_socket = DIR/gain.sock.steps, mode 0600
        Initialize (gRPC), then framed DoStepRequests on the step socket
            -> the answers StepStream gives, then the end (code 0) after the half-close
        a stranger's request without the secret -> the end with PERMISSION_DENIED,
            the owner's next request -> ABORTED naming it
        a frame over the receive limit -> RESOURCE_EXHAUSTED, unread
        frames in uneven pieces (a split header, a long frame in parts) -> whole frames' answers
        the connection closed before Terminate -> the run ends, the next Initialize is served

The client below is a raw unix socket and the generated messages, nothing of the runtime.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import socket
import stat
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import grpc
import pytest

from coupler.testing import free_port
from coupler.v1 import component_pb2 as pb
from coupler.v1 import component_pb2_grpc as pb_grpc

pytestmark = pytest.mark.timeout(120)

HEADER = struct.Struct("<IB")  # payload length (uint32 LE, the header not counted), kind (uint8)
STEP, END = 0, 1
OK, DEADLINE_EXCEEDED, PERMISSION_DENIED, RESOURCE_EXHAUSTED, ABORTED = 0, 4, 7, 8, 10


class Gain:
    """The gain example served on a unix socket, and a gRPC stub to it."""

    def __init__(self, folder: Path, *, umask: int | None = None) -> None:
        self.path = folder / "gain.sock"
        self.process = subprocess.Popen(
            [sys.executable, "-m", "coupler.examples", "gain", "--socket", str(self.path)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            umask=-1 if umask is None else umask,
        )
        assert self.process.stdout is not None
        assert "unix:///" in self.process.stdout.readline()
        self.channel = grpc.insecure_channel(f"unix:{self.path}")
        self.stub = pb_grpc.GRPCComponentServiceStub(self.channel)

    def initialize(self, run_id: str, secret: bytes) -> None:
        self.stub.Initialize(
            pb.InitializeRequest(
                run_id=run_id, run_secret=secret, start_time=0.0, step_size=0.1, lease_seconds=600
            ),
            timeout=10,
        )

    def terminate(self, run_id: str, secret: bytes) -> None:
        self.stub.Terminate(pb.TerminateRequest(run_id=run_id, run_secret=secret), timeout=10)

    def memory(self) -> int:
        """The participant's resident memory [kB]."""
        for line in Path(f"/proc/{self.process.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        raise AssertionError("no VmRSS")

    def stop(self) -> None:
        self.channel.close()
        self.process.terminate()
        self.process.wait(20)
        assert self.process.stdout is not None
        self.process.stdout.close()


@pytest.fixture
def gain() -> Iterator[Gain]:
    folder = Path(os.path.realpath("/tmp")) / f"ss-{os.getpid()}-{free_port()}"
    folder.mkdir(mode=0o700)
    served = Gain(folder)
    yield served
    served.stop()
    for entry in folder.iterdir():
        entry.unlink()
    folder.rmdir()


class StepSocket:
    """A connection to a step socket: framed requests out, framed answers in."""

    def __init__(self, path: str) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(20)
        self.sock.connect(path)

    def send(self, request: pb.DoStepRequest) -> None:
        payload = request.SerializeToString()
        self.sock.sendall(HEADER.pack(len(payload), STEP) + payload)

    def receive(self) -> tuple[int, bytes]:
        size, kind = HEADER.unpack(self.exactly(HEADER.size))
        return kind, self.exactly(size)

    def step(self, request: pb.DoStepRequest) -> pb.DoStepResponse:
        self.send(request)
        kind, payload = self.receive()
        assert kind == STEP, pb.StepSocketEnd.FromString(payload)
        return pb.DoStepResponse.FromString(payload)

    def end(self) -> pb.StepSocketEnd:
        """The participant's last frame, and then the connection's end."""
        kind, payload = self.receive()
        assert kind == END
        with contextlib.suppress(ConnectionResetError):  # it closed with a request unread
            assert self.sock.recv(1) == b""
        return pb.StepSocketEnd.FromString(payload)

    def exactly(self, size: int) -> bytes:
        data = bytearray()
        while len(data) < size:
            chunk = self.sock.recv(size - len(data))
            assert chunk, f"the connection ended after {len(data)} of {size} bytes"
            data += chunk
        return bytes(data)

    def close(self) -> None:
        self.sock.close()


def requests(run_id: str, secret: bytes, steps: int) -> list[pb.DoStepRequest]:
    """A run's step requests, with a value on an input of every type."""
    return [
        pb.DoStepRequest(
            run_id=run_id,
            run_secret=secret,
            current_time=k / 10,
            step_size=0.1,
            inputs=[
                pb.VariableBinding(channel="u", real=1.5 * k),
                pb.VariableBinding(channel="n", integer=k),
                pb.VariableBinding(channel="flag", boolean=k % 2 == 0),
                pb.VariableBinding(channel="label", text=f"step {k}"),
                pb.VariableBinding(channel="blob", binary=bytes([k]) * (200_000 * (k % 2))),
            ],
        )
        for k in range(steps)
    ]


def test_the_step_socket_answers_as_step_stream_does(gain: Gain) -> None:
    described = gain.stub.Describe(pb.DescribeRequest(), timeout=10)
    assert described.capabilities.step_socket == f"{gain.path}.steps"
    mode = os.stat(described.capabilities.step_socket).st_mode
    assert stat.S_ISSOCK(mode) and stat.S_IMODE(mode) == 0o600

    secret = secrets.token_bytes(32)
    gain.initialize("over-stream", secret)
    streamed = list(gain.stub.StepStream(iter(requests("over-stream", secret, 6)), timeout=20))
    gain.terminate("over-stream", secret)

    gain.initialize("over-socket", secret)
    steps = StepSocket(described.capabilities.step_socket)
    answers = [steps.step(request) for request in requests("over-socket", secret, 6)]
    gain.terminate("over-socket", secret)
    steps.sock.shutdown(socket.SHUT_WR)
    assert steps.end() == pb.StepSocketEnd(code=OK)
    steps.close()
    for answer in (*answers, *streamed):  # each says what its step cost (its own figure)
        assert answer.step_seconds > 0
        answer.ClearField("step_seconds")
    assert answers == streamed
    assert len(answers[1].outputs[-1].binary) == 200_000  # a long Binary value, as sent


def test_frames_in_uneven_pieces_are_answered_as_whole_ones(gain: Gain) -> None:
    """A frame's header split, a long frame (over the participant's buffer of short frames)
    whose header arrives with its first bytes and the rest in pieces: the answers are those
    of whole frames (the participant reads long frames into a buffer of their own)."""
    secret = secrets.token_bytes(32)
    gain.initialize("whole", secret)
    whole = StepSocket(f"{gain.path}.steps")
    expected = [whole.step(request) for request in requests("whole", secret, 4)]
    gain.terminate("whole", secret)
    whole.close()

    gain.initialize("pieces", secret)
    steps = StepSocket(f"{gain.path}.steps")
    answers = []
    for request in requests("pieces", secret, 4):
        payload = request.SerializeToString()
        frame = HEADER.pack(len(payload), STEP) + payload
        cuts = sorted({c for c in (1, 3, 9, 70_000, len(frame) - 1) if c < len(frame)})
        for start, end in zip([0, *cuts], [*cuts, len(frame)], strict=True):
            steps.sock.sendall(frame[start:end])
            time.sleep(0.01)  # each piece read on its own
        kind, answer = steps.receive()
        assert kind == STEP, pb.StepSocketEnd.FromString(answer)
        answers.append(pb.DoStepResponse.FromString(answer))
    gain.terminate("pieces", secret)
    steps.close()
    assert [a.outputs for a in answers] == [e.outputs for e in expected]
    assert len(answers[1].outputs[-1].binary) == 200_000


def test_a_request_without_the_secret_is_refused_and_the_owner_told(gain: Gain) -> None:
    secret = secrets.token_bytes(32)
    gain.initialize("owned", secret)
    path = f"{gain.path}.steps"
    owner = StepSocket(path)
    first, second = requests("owned", secret, 2)
    owner.step(first)

    stranger = StepSocket(path)
    stranger.send(requests("owned", b"guessed-secret-0123456789", 1)[0])
    refused = stranger.end()
    assert refused.code == PERMISSION_DENIED
    assert "does not carry that run's secret" in refused.message
    stranger.close()

    owner.send(second)
    aborted = owner.end()
    assert aborted.code == ABORTED
    assert "Gain refused the run: a call with a wrong secret arrived from unix:" in aborted.message
    owner.close()  # the refused loop ended the run with it, as a refused StepStream does


def test_a_frame_over_the_receive_limit_is_refused_unread(gain: Gain) -> None:
    secret = secrets.token_bytes(32)
    gain.initialize("large", secret)
    before = gain.memory()
    size = 100 * 1024 * 1024  # over the gain's 64 MiB of values plus 8 MiB (nothing declared)
    steps = StepSocket(f"{gain.path}.steps")

    def flood() -> None:
        try:
            steps.sock.sendall(HEADER.pack(size, STEP))
            chunk = bytes(1024 * 1024)
            for _ in range(size // len(chunk)):
                steps.sock.sendall(chunk)
        except OSError:
            pass  # the participant closed the connection

    sender = threading.Thread(target=flood)
    sender.start()
    end = steps.end()
    steps.sock.shutdown(socket.SHUT_RDWR)
    sender.join(30)
    steps.close()
    assert end.code == RESOURCE_EXHAUSTED
    assert f"a frame of {size} bytes" in end.message
    assert f"receive limit of {(64 + 8) * 1024 * 1024} bytes" in end.message
    assert gain.memory() - before < 32 * 1024  # kB: the frame was not read into memory
    gain.terminate("large", secret)


def test_a_run_ends_with_its_step_socket_connection(gain: Gain) -> None:
    secret = secrets.token_bytes(32)
    gain.initialize("lost", secret)
    steps = StepSocket(f"{gain.path}.steps")
    steps.step(requests("lost", secret, 1)[0])
    steps.close()  # the orchestrator's process is gone: no half-close, no Terminate
    deadline = time.monotonic() + 5
    while True:
        try:
            gain.initialize("next", secret)
            break
        except grpc.RpcError as exc:
            assert exc.code() == grpc.StatusCode.FAILED_PRECONDITION
            assert time.monotonic() < deadline, "the lost connection's run did not end"
            time.sleep(0.05)
    gain.terminate("next", secret)


def test_headers_alone_make_the_participant_hold_nothing_they_announce(gain: Gain) -> None:
    """40 connections, each a 5-byte header announcing a 72 MiB frame (the receive limit),
    then silence: the participant grew by gigabytes, allocating each announced frame before any
    byte of it came. Now a frame's buffer grows with what arrives, and the fifth and later
    connections are refused at once (RESOURCE_EXHAUSTED)."""
    secret = secrets.token_bytes(32)
    gain.initialize("headers", secret)
    before = gain.memory()
    size = (64 + 8) * 1024 * 1024
    connections = [StepSocket(f"{gain.path}.steps") for _ in range(40)]
    try:
        for steps in connections:
            with contextlib.suppress(OSError):  # a refused one may be closed already
                steps.sock.sendall(HEADER.pack(size, STEP) + b"x" * 1000)
        time.sleep(1.0)
        grown = gain.memory() - before
        refused = 0
        for steps in connections[4:]:
            end = steps.end()
            refused += end.code == RESOURCE_EXHAUSTED and "connections at once" in end.message
    finally:
        for steps in connections:
            steps.close()
    assert grown < 64 * 1024, f"the participant grew by {grown} kB"  # under 300 MB in all
    assert gain.memory() < 300 * 1024
    assert refused == 36


@pytest.mark.slow
def test_a_frame_that_stalls_ends_its_connection(gain: Gain) -> None:
    """A header and the frame's first bytes, then nothing: after FRAME_STALL_S (10 s) the
    connection ends DEADLINE_EXCEEDED (it waited for the rest for good)."""
    from coupler.step_socket import FRAME_STALL_S

    secret = secrets.token_bytes(32)
    gain.initialize("stalled", secret)
    steps = StepSocket(f"{gain.path}.steps")
    steps.sock.settimeout(FRAME_STALL_S + 20)
    started = time.monotonic()
    steps.sock.sendall(HEADER.pack(1_000_000, STEP) + b"x" * 100_000)
    end = steps.end()
    waited = time.monotonic() - started
    steps.close()
    assert end.code == DEADLINE_EXCEEDED and "waited 10 s for its next bytes" in end.message
    assert waited >= FRAME_STALL_S


def test_the_grpc_socket_is_the_owners_alone_whatever_the_umask(tmp_path: Path) -> None:
    """Served under ``umask 000`` the gRPC unix socket was world-connectable (0777): it is made
    0600, as the step socket is."""
    folder = Path(os.path.realpath("/tmp")) / f"um-{os.getpid()}-{free_port()}"
    folder.mkdir(mode=0o700)
    served = Gain(folder, umask=0)
    try:
        for path in (served.path, Path(f"{served.path}.steps")):
            mode = os.stat(path).st_mode
            assert stat.S_ISSOCK(mode) and stat.S_IMODE(mode) == 0o600, (path, oct(mode))
    finally:
        served.stop()
        for entry in folder.iterdir():
            entry.unlink()
        folder.rmdir()
