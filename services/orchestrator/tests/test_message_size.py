"""Large messages: a camera frame through every hop, and one over the message limit.

    Frames (frame: Binary, `size` bytes) --frame--> Gain.blob --> Gain.blob_out
      participant       orchestrator            participant      orchestrator

A 1.44 MB frame (800 x 600 x 3) passes both ways; a frame over the limit -- the run's
(``--max-message-size``) or a participant server's (``max_message_bytes``), sending or
receiving -- fails the run with one error naming the channel, its size, the limit and the fix.
Over both step paths (the native step channel and grpc.aio), with ``coupler run`` as a process.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import ExitStack
from pathlib import Path

import pytest

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.examples.gain import GainParticipant
from coupler.participant import Participant, Values
from coupler.testing import SystemStructure, remote

from .conftest import Coupler, serving

FRAME = 800 * 600 * 3
MIB = 1024 * 1024
SSD = SystemStructure(
    "Frames",
    components=[
        remote("Camera", "grpc://127.0.0.1:${CAMERA_PORT}", outputs=["frame"]),
        remote("Gain", "grpc://127.0.0.1:${GAIN_PORT}", inputs=["blob"], outputs=["blob_out"]),
    ],
    connections=[("Camera.frame", "Gain.blob")],
    stop_time=0.3,
)


class Camera(Participant):
    """One Binary output: ``size`` bytes per step, a different pattern each step."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.steps = 0

    async def describe(self) -> Description:
        frame = Channel(name="frame", causality=Causality.OUTPUT, type=ValueType.BINARY)
        return Description(name="Camera", channels=(frame,), implementation="tests.Camera")

    async def initialize(self, setup: RunSetup) -> Values:
        self.steps = 0
        return {"frame": b""}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self.steps += 1
        return {"frame": bytes([self.steps % 256]) * self.size}

    async def terminate(self, reason: str = "") -> None:
        self.steps = 0


@pytest.fixture
def ssd(tmp_path: Path) -> Path:
    return SSD.write(tmp_path / "frames.ssd")


@pytest.fixture
def fleet(monkeypatch: pytest.MonkeyPatch) -> Iterator[Fleet]:
    with ExitStack() as stack:
        yield Fleet(stack, monkeypatch)


class Fleet:
    """Camera and Gain served in this process (the run is a process of its own)."""

    def __init__(self, stack: ExitStack, monkeypatch: pytest.MonkeyPatch) -> None:
        self.stack, self.monkeypatch = stack, monkeypatch

    def serve(
        self,
        size: int = 0,
        *,
        camera: Participant | None = None,
        camera_limit: int = 64 * MIB,
        gain_limit: int = 64 * MIB,
    ) -> None:
        for name, participant, limit in (
            ("CAMERA", camera or Camera(size), camera_limit),
            ("GAIN", GainParticipant(), gain_limit),
        ):
            server = self.stack.enter_context(serving(participant, max_message_bytes=limit))
            self.monkeypatch.setenv(f"{name}_PORT", str(server.port))


def run(ssd: Path, out: Path, step_path: str, *options: str) -> tuple[int, str, dict]:
    env = {"COUPLER_NATIVE_STEPS": "1" if step_path == "native" else "0"}
    outcome = Coupler.process("run", ssd, "--step", "0.1", "--out", out, *options, env=env)
    return outcome.code, outcome.err, Coupler.summary(out)


def test_a_camera_frame_passes_every_hop(
    ssd: Path, tmp_path: Path, fleet: Fleet, step_path: str
) -> None:
    fleet.serve(FRAME)
    code, err, summary = run(ssd, tmp_path / "out", step_path, "--output-variables", "Gain.*")
    assert code == 0, err
    assert summary["status"] == "completed"
    paths = {member["step_path"]["path"] for member in summary["participants"].values()}
    assert paths == {"native step channel" if step_path == "native" else "Python"}
    assert summary["steps"] == 3


def test_a_frame_over_the_runs_limit_names_its_channel(
    ssd: Path, tmp_path: Path, fleet: Fleet, step_path: str
) -> None:
    """The answer arrives (under the participant's limit) and the orchestrator refuses it."""
    fleet.serve(2 * MIB)
    code, err, summary = run(ssd, tmp_path / "out", step_path, "--max-message-size", "1")
    assert code != 0
    expected = (
        "Camera.DoStep [RESOURCE_EXHAUSTED]: output Camera.frame carries 2097152 bytes: over the "
        "message limit of 1048576 bytes (1 MiB); raise the limit on both sides (coupler run "
        "--max-message-size MiB"
    )
    assert expected in err
    assert "Traceback" not in err
    assert summary["status"] == "failed"
    assert expected in summary["reason"]


def test_a_frame_over_the_senders_limit_names_its_channel(
    ssd: Path, tmp_path: Path, fleet: Fleet, step_path: str
) -> None:
    """The participant's server refuses to send it, naming the channel."""
    fleet.serve(2 * MIB, camera_limit=MIB)
    code, err, summary = run(ssd, tmp_path / "out", step_path)
    assert code != 0
    assert (
        "Camera.DoStep [RESOURCE_EXHAUSTED]: output 'frame' carries 2097152 bytes: over the "
        "message limit of 1048576 bytes (1 MiB)"
    ) in err
    assert summary["status"] == "failed"


def test_a_frame_over_the_receivers_limit_names_its_channel(
    ssd: Path, tmp_path: Path, fleet: Fleet, step_path: str
) -> None:
    """Gain's server takes at most 1 MiB: the orchestrator's request with the frame is refused
    there, naming Gain's input."""
    fleet.serve(FRAME, gain_limit=MIB)
    code, err, summary = run(ssd, tmp_path / "out", step_path)
    assert code != 0
    assert (
        "Gain.DoStep [RESOURCE_EXHAUSTED]: input 'blob' carries 1440000 bytes: over the message "
        "limit of 1048576 bytes (1 MiB)"
    ) in err
    assert summary["status"] == "failed"


def test_the_limit_must_be_a_size(ssd: Path, tmp_path: Path) -> None:
    outcome = Coupler.process("run", ssd, "--max-message-size", "0", "--out", tmp_path / "o")
    assert outcome.code == 2
    assert "--max-message-size: '0' is not a size in MiB above 0 and at most 1024" in outcome.err
