"""The native step channel (coupler_orchestrator.master.native_step_channel): built here,
chosen by default, the same bytes in results.csv as Python's grpc.aio, and the same answers to
a participant that ends the run or answers outside its description.

test_faults.py runs the killed, stopped and hung participants over both step paths,
test_secure_run.py mutual TLS with a token.
"""

from __future__ import annotations

import asyncio
import contextlib
import shutil
import socket
import struct
import tempfile
import threading
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import grpc
import pytest
from grpc_health.v1 import health, health_pb2_grpc

from coupler import wire
from coupler.channels import RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError, ParticipantTimeout
from coupler.examples.gain import GainParticipant
from coupler.participant import EndRun, Values
from coupler.v1 import component_pb2 as pb
from coupler.v1 import component_pb2_grpc as pb_grpc
from coupler_orchestrator import ssp
from coupler_orchestrator.master import native_step_channel as steps
from coupler_orchestrator.native import MISSING
from coupler_orchestrator.options import NATIVE_STEPS_VARIABLE, RunOptions
from coupler_orchestrator.pipeline import participants

from ..support import Coupler, FailingGain, Outcome, require_native, serving
from ..support.faults import SSD, gain

pytestmark = pytest.mark.usefixtures("fmus")


@pytest.fixture(scope="module")
def native() -> Iterator[None]:
    """The step channel, loaded from coupler-native."""
    require_native(steps.library)
    yield


@pytest.fixture
def ssd(tmp_path: Path) -> Path:
    return SSD.write(tmp_path / "faults.ssd")


def component(source: str = "grpc://127.0.0.1:1") -> ssp.Component:
    return ssp.Component(name="Gain", type=ssp.GRPC_TYPE, source=source, connectors=(), line=1)


@pytest.mark.usefixtures("native")
def test_remote_participants_step_natively_unless_told_not_to(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The runner gives each remote participant its step transport (``steps.transport``):
    the native step channel, unless --no-native-steps or COUPLER_NATIVE_STEPS=0 say no."""
    created = participants.create(component(), RunOptions(), steps=steps.transport())
    assert type(created) is RemoteParticipant and type(created.steps) is steps.NativeSteps
    assert steps.transport(RunOptions(native_steps=False).native_steps)() is None
    plain = participants.create(component(), RunOptions())
    assert type(plain) is RemoteParticipant and plain.steps is None
    monkeypatch.setenv(NATIVE_STEPS_VARIABLE, "0")  # read once, where the run's options are
    assert RunOptions().switched().native_steps is False and RunOptions().step_socket
    assert steps.transport(RunOptions().switched().native_steps)() is None
    assert RunOptions().switched({"COUPLER_STEP_SOCKET": "no"}).step_socket is False


@pytest.mark.usefixtures("native")
@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_the_same_bytes_as_grpc_aio(
    coupler: Coupler,
    ssd: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    algorithm: str,
) -> None:
    """FMU -> remote Gain -> FMU: the remote member's request leaves before the FMUs compute
    (Jacobi) or in order (Gauss-Seidel); results.csv byte for byte as over grpc.aio."""
    recorded = {}
    stepped = {
        "native": {"path": "native step channel", "reason": "its StepStream over C++ gRPC"},
        "aio": {"path": "Python", "reason": steps.why_python(None, asked=False)},
    }
    with gain(monkeypatch):
        for path, flag in (("native", ()), ("aio", ("--no-native-steps",))):
            out = tmp_path / path
            outcome = coupler(
                "run", ssd, "--out", out, "--step", "0.1", "--algorithm", algorithm, *flag
            )
            assert outcome.code == 0, outcome.err
            recorded[path] = (out / "results.csv").read_bytes()
            gain_summary = coupler.summary(out)["participants"]["Gain"]
            assert gain_summary["steps"] == 200
            assert 0 < gain_summary["do_step_latency_ms"]["p50"] < 1000
            assert gain_summary["step_path"] == stepped[path]
    assert recorded["native"] == recorded["aio"]
    assert recorded["native"].count(b"\n") == 202  # header and t = 0 .. 20 s


class Ending(GainParticipant):
    """Asks to end the run at t >= 1 s."""

    async def do_step(self, time_s: float, step: float, inputs: Mapping[str, object]) -> Values:
        outputs = await super().do_step(time_s, step, inputs)  # type: ignore[arg-type]
        if time_s + step >= 1 - 1e-9:
            raise EndRun("the train has arrived", outputs)
        return outputs


class Strange(GainParticipant):
    """Answers with an output it never described from t >= 0.5 s."""

    async def do_step(self, time_s: float, step: float, inputs: Mapping[str, object]) -> Values:
        outputs = await super().do_step(time_s, step, inputs)  # type: ignore[arg-type]
        if time_s >= 0.5 - 1e-9:
            outputs["z"] = 1.0
        return outputs


def run_against(
    participant: GainParticipant,
    coupler: Coupler,
    ssd: Path,
    out: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> Outcome:
    """``coupler run`` of the gain scenario, its Gain served by ``participant``."""
    with serving(participant) as server:
        monkeypatch.setenv("GAIN_PORT", str(server.port))
        return coupler("run", ssd, "--out", out, "--step", "0.1")


@pytest.mark.usefixtures("native")
def test_a_participant_ending_the_run_is_heard(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    outcome = run_against(Ending("Gain"), coupler, ssd, tmp_path, monkeypatch)
    assert outcome.code == 0, outcome.err
    summary = coupler.summary(tmp_path)
    assert summary["status"] == "terminated"
    assert "Gain asked to end the run at t=1 s: the train has arrived" in summary["reason"]
    assert coupler.column(tmp_path, "time")[-1] == pytest.approx(1.0)


@pytest.mark.usefixtures("native")
def test_an_answer_outside_the_description_fails_the_run(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    outcome = run_against(Strange("Gain"), coupler, ssd, tmp_path, monkeypatch)
    assert outcome.code == 1
    reason = coupler.summary(tmp_path)["reason"]
    assert "Gain.DoStep" in reason and "'z'" in reason, reason
    assert len(coupler.results(tmp_path)) == 6  # t = 0 .. 0.5 s, nothing lost


@pytest.mark.usefixtures("without_coupler_native")
def test_without_coupler_native_remote_steps_take_grpc_aio() -> None:
    """Without coupler-native: the run takes the Python path and says why."""
    assert not steps.enabled()
    created = participants.create(component(), RunOptions(), steps=steps.transport())
    assert type(created) is RemoteParticipant and created.steps is None
    assert steps.why_python(created, asked=True) == MISSING


@pytest.mark.usefixtures("native")
async def test_a_step_in_two_halves() -> None:
    """NativeSteps given to a RemoteParticipant, after Initialize: split() is itself; send,
    then receive, gives what do_step over grpc.aio gives; after Terminate the stream is gone."""
    with serving(GainParticipant("Gain")) as one, serving(GainParticipant("Gain")) as other:
        transport = steps.NativeSteps()
        native = RemoteParticipant(f"grpc://127.0.0.1:{one.port}", steps=transport)
        aio = RemoteParticipant(f"grpc://127.0.0.1:{other.port}")
        for p in (native, aio):
            await p.open()
            await p.initialize(RunSetup(run_id=f"halves-{id(p)}", start_time=0.0, step_size=0.1))
        halves = transport.split()
        assert halves is transport
        for k in range(3):
            await same_answers(halves, aio, k, {"u": float(k)})
        for k in range(3, 6):  # frames: sent from pieces, cut out of the answer (wire)
            frame = bytes(range(256)) * (5_000 + k) + bytes([k])
            await same_answers(halves, aio, k, {"u": 1.0, "blob": frame})
        await terminated(native, aio)
        assert transport.split() is None


async def same_answers(
    halves: steps.NativeSteps, aio: RemoteParticipant, k: int, inputs: dict[str, Any]
) -> None:
    """Step ``k`` sent and received in halves answers what do_step over grpc.aio answers (the
    gain's ``blob_out`` is its ``blob`` reversed)."""
    halves.send(k * 0.1, 0.1, inputs)
    outputs = halves.receive()
    if "blob" in inputs:
        assert outputs["blob_out"] == inputs["blob"][::-1]
    assert outputs == await aio.do_step(k * 0.1, 0.1, inputs)


async def terminated(*participants: RemoteParticipant) -> None:
    for p in participants:
        await p.terminate("done")
        await p.close()


class Sleepy(GainParticipant):
    """Takes 3 s over the step that starts at t >= 0.2 s."""

    async def do_step(self, time_s: float, step: float, inputs: Mapping[str, object]) -> Values:
        if time_s >= 0.2 - 1e-9:
            await asyncio.sleep(3.0)
        return await super().do_step(time_s, step, inputs)  # type: ignore[arg-type]


@pytest.mark.usefixtures("native")
async def test_a_step_in_two_halves_over_the_step_socket(tmp_path: Path) -> None:
    """A participant on a unix socket offers its step socket; NativeSteps takes it (the same
    cs_* calls, target steps:PATH): what do_step over grpc.aio gives, frames sent from pieces;
    the participant's refusal (INTERNAL) and a step past the deadline end it as they end a
    StepStream."""
    folder = Path(tempfile.mkdtemp(prefix="ns-", dir="/tmp"))  # a socket's path: 107 bytes
    sockets = [folder / f"{name}.sock" for name in ("one", "other", "failing", "sleepy")]
    with (
        serving(GainParticipant("Gain"), unix_socket=sockets[0]) as one,
        serving(GainParticipant("Gain"), unix_socket=sockets[1]) as other,
        serving(FailingGain("Gain", fail_at=0.2), unix_socket=sockets[2]) as failing,
        serving(Sleepy("Gain"), unix_socket=sockets[3]) as sleepy,
    ):
        assert one.step_socket == folder / "one.sock.steps"
        transport = steps.NativeSteps()
        native = RemoteParticipant(one.address, steps=transport)
        aio = RemoteParticipant(other.address, streaming=False)
        for p in (native, aio):
            await p.open()
            await p.initialize(RunSetup(run_id=f"socket-{id(p)}", start_time=0.0, step_size=0.1))
        assert transport.described == (
            "native step socket",
            f"its step socket {one.step_socket}, without gRPC",
        )
        halves = transport.split()
        assert halves is transport
        for k in range(6):
            frame = bytes(range(256)) * (300 * k) + bytes([k])  # long ones in pieces
            await same_answers(halves, aio, k, {"u": float(k), "blob": frame, "label": f"step {k}"})
        await terminated(native, aio)
        assert transport.split() is None

        for server, error, status in (
            (failing, ParticipantError, "INTERNAL"),
            (sleepy, ParticipantTimeout, "DEADLINE_EXCEEDED"),
        ):
            transport = steps.NativeSteps()
            remote = RemoteParticipant(server.address, steps=transport, call_timeout=1.0)
            await remote.open()
            await remote.initialize(RunSetup(run_id="ends", start_time=0.0, step_size=0.1))
            assert transport.described[0] == "native step socket"
            for k in range(2):
                transport.send(k * 0.1, 0.1, {"u": 1.0})
                transport.receive()
            transport.send(0.2, 0.1, {"u": 1.0})
            with pytest.raises(error) as ended:
                transport.receive()
            assert ended.value.status == status, ended.value
            if status == "INTERNAL":
                assert "gain overheated at t=0.2" in str(ended.value)
                await remote.terminate("failed")
            await remote.close()  # the sleepy one's run ends with its connection
    shutil.rmtree(folder, ignore_errors=True)


GARBLED = [b"\x0a\x05ab"]
"""An answer that is no DoStepResponse: outputs of 5 bytes, 2 of them there."""
TWICE = [
    pb.DoStepResponse(
        outputs=[
            pb.VariableBinding(channel="y", real=1.0),
            pb.VariableBinding(channel="x", real=2.0),
            pb.VariableBinding(channel="count", integer=0),
            pb.VariableBinding(channel="inverted", boolean=True),
            pb.VariableBinding(channel="echo", text=""),
            pb.VariableBinding(channel="blob_out", binary=b""),
        ]
    ).SerializeToString()
] * 2
"""One well-formed answer, sent twice for every request."""


class FakeSteps:
    """A step socket answering each request's frame with the frames ``answers``."""

    def __init__(self, path: Path, answers: list[bytes]) -> None:
        self.answers = answers
        self.server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.server.bind(str(path))
        self.server.listen()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        with contextlib.suppress(OSError):
            connection, _ = self.server.accept()
            with connection:
                while header := connection.recv(5, socket.MSG_WAITALL):
                    size, _ = struct.unpack("<IB", header)
                    connection.recv(size, socket.MSG_WAITALL)
                    connection.sendall(
                        b"".join(struct.pack("<IB", len(a), 0) + a for a in self.answers)
                    )

    def close(self) -> None:
        self.server.close()
        self.thread.join(5)


@pytest.mark.usefixtures("native")
@pytest.mark.parametrize(
    ("answers", "says"),
    [
        (GARBLED, "Gain.DoStep [INTERNAL]: its answer is not a DoStepResponse"),
        (TWICE, "Gain.DoStep [INTERNAL]: an answer arrived on the step socket before its request"),
    ],
    ids=["not a DoStepResponse", "two answers to one request"],
)
def test_answers_the_step_socket_did_not_ask_for_fail_the_run(
    coupler: Coupler,
    ssd: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    answers: list[bytes],
    says: str,
) -> None:
    """A well-framed answer that is not a DoStepResponse (it ended with a DecodeError's
    traceback in the run_failed line), or two answers to every request (every later row was
    the step before's, and the run completed): the run fails at once, in one sentence."""
    folder = Path(tempfile.mkdtemp(prefix="gs-", dir="/tmp"))  # a socket's path: 107 bytes
    monkeypatch.setenv("GAIN_PORT", "1")  # the SSD's address; --address moves it
    try:
        with serving(GainParticipant("Gain"), unix_socket=folder / "gain.sock") as server:
            assert server.step_socket is not None
            server.step_socket.unlink()  # its path now leads to the fake one
            fake = FakeSteps(server.step_socket, answers)
            try:
                outcome = coupler(
                    "run", ssd, "--out", tmp_path / "o", "--step", "0.1",
                    "--address", f"Gain={server.address}",
                )  # fmt: skip
            finally:
                fake.close()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    assert outcome.code == 1, outcome
    summary = coupler.summary(tmp_path / "o")
    assert summary["reason"].startswith(says), summary["reason"]
    assert summary["steps"] <= 1
    assert "Traceback" not in outcome.err


class TwiceOverStepStream(pb_grpc.GRPCComponentServiceServicer):  # type: ignore[misc]
    """The protocol written by hand, as another language would: the gain's Describe, and a
    StepStream that answers every request twice."""

    async def Describe(self, request: Any, context: Any) -> pb.DescribeResponse:
        described = wire.description_to_pb(await GainParticipant("Gain").describe())
        described.capabilities.streaming = True
        return described

    async def Initialize(self, request: Any, context: Any) -> pb.InitializeResponse:
        return pb.InitializeResponse.FromString(TWICE[0])  # the same outputs (field 1)

    async def StepStream(self, requests: Any, context: Any) -> Any:
        async for _ in requests:
            for answer in TWICE:
                yield pb.DoStepResponse.FromString(answer)

    async def Terminate(self, request: Any, context: Any) -> pb.TerminateResponse:
        return pb.TerminateResponse()


@contextlib.contextmanager
def answering_twice() -> Iterator[int]:
    """``TwiceOverStepStream`` on a real grpc.aio server (with the health service), in a
    thread; its port."""
    ready, port = threading.Event(), [0]
    ends: list[tuple[asyncio.AbstractEventLoop, asyncio.Event]] = []

    async def serve() -> None:
        server = grpc.aio.server()
        pb_grpc.add_GRPCComponentServiceServicer_to_server(TwiceOverStepStream(), server)
        health_pb2_grpc.add_HealthServicer_to_server(health.aio.HealthServicer(), server)
        port[0] = server.add_insecure_port("127.0.0.1:0")
        await server.start()
        ends.append((asyncio.get_running_loop(), asyncio.Event()))
        ready.set()
        await ends[0][1].wait()
        await server.stop(0)

    thread = threading.Thread(target=asyncio.run, args=(serve(),))
    thread.start()
    try:
        ready.wait(10)
        yield port[0]
    finally:
        if ends:
            loop, end = ends[0]
            loop.call_soon_threadsafe(end.set)
        thread.join(10)


@pytest.mark.parametrize("path", ["native", "grpc.aio"])
def test_two_answers_to_one_request_on_a_step_stream_fail_the_run(
    coupler: Coupler, ssd: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, path: str
) -> None:
    """Over a StepStream (gRPC), each step read the answer meant for the step before and the
    run completed; the extra answers are found when the stream ends, and the run fails."""
    if path == "native":
        require_native(steps.library)
    with answering_twice() as port:
        monkeypatch.setenv("GAIN_PORT", str(port))
        extra = [] if path == "native" else ["--no-native-steps"]
        outcome = coupler("run", ssd, "--out", tmp_path / "o", "--step", "0.1", *extra)
    assert outcome.code == 1, outcome
    reason = coupler.summary(tmp_path / "o")["reason"]
    assert "Gain.Terminate [ABORTED]: 200 step answers came after the run's last request" in reason
    assert "answered a request twice" in reason and "after the run's last step" in reason
