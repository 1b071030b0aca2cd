"""Large messages: a camera frame through every hop, and one over the message limit.

    Frames (frame: Binary, `size` bytes) --frame--> Gain.blob --> Gain.blob_out
      participant       orchestrator            participant      orchestrator

    Declared (frame: at most `maximum` bytes) --frame--> Viewer.frame (at most `accepts`)

A 1.44 MB frame (800 x 600 x 3) passes both ways; a frame over the limit -- the run's
(``--max-message-size``) or a participant server's (``max_message_bytes``), sending or
receiving -- fails the run with one error naming the channel, its size, the limit and the fix.
With declared maxima (``Channel.max_bytes``) the limits come from the declarations: a 2 MB
channel carries the frame between servers whose default is 1 MiB; an output declaring more than
its input accepts is refused before anything runs; a frame over its declared maximum fails the
run naming the channel, its size and the maximum, keeping the rows before it.
Over both step paths (the native step channel and grpc.aio), with ``coupler run`` as a process.
"""

from __future__ import annotations

import asyncio
import zipfile
from collections.abc import Mapping
from pathlib import Path

import pytest

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.fmu import FmuParticipant
from coupler.participant import Participant, Values
from coupler.testing import SystemStructure, remote
from coupler_orchestrator import recording
from coupler_orchestrator.pipeline.replay import ReplayParticipant

from .support import Coupler, serving
from .support.frames import FRAME, MIB, SSD, Camera, Fleet


@pytest.fixture
def ssd(tmp_path: Path) -> Path:
    return SSD.write(tmp_path / "frames.ssd")


async def described(participant: Participant) -> Description:
    """``participant``'s description, closed again after."""
    try:
        return await participant.describe()
    finally:
        await participant.close()


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


DECLARED = SystemStructure(
    "Declared",
    components=[
        remote("Camera", "grpc://127.0.0.1:${CAMERA_PORT}", outputs=["frame"]),
        remote("Viewer", "grpc://127.0.0.1:${VIEWER_PORT}", inputs=["frame"], outputs=["size"]),
    ],
    connections=[("Camera.frame", "Viewer.frame")],
    stop_time=0.4,
)


class Viewer(Participant):
    """Takes frames of at most ``accepts`` bytes (``frame``) and tells their size (``size``)."""

    def __init__(self, accepts: int) -> None:
        self.accepts = accepts

    async def describe(self) -> Description:
        channels = (
            Channel(
                name="frame",
                causality=Causality.INPUT,
                type=ValueType.BINARY,
                start=b"",
                max_bytes=self.accepts,
            ),
            Channel(name="size", causality=Causality.OUTPUT, type=ValueType.INTEGER),
        )
        return Description(name="Viewer", channels=channels, implementation="tests.Viewer")

    async def initialize(self, setup: RunSetup) -> Values:
        return {"size": len(setup.inputs.get("frame", b""))}  # type: ignore[arg-type]

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return {"size": len(inputs["frame"])}  # type: ignore[arg-type]

    async def terminate(self, reason: str = "") -> None:
        return None


@pytest.fixture
def declared(tmp_path: Path) -> Path:
    return DECLARED.write(tmp_path / "declared.ssd")


def serve_declared(fleet: Fleet, camera: Camera, accepts: int, *, limit: int = 64 * MIB) -> None:
    """Camera and Viewer, their servers' default limit ``limit``."""
    for name, participant in (("CAMERA", camera), ("VIEWER", Viewer(accepts))):
        server = fleet.stack.enter_context(serving(participant, max_message_bytes=limit))
        fleet.monkeypatch.setenv(f"{name}_PORT", str(server.port))


def test_a_declared_channel_carries_a_frame_past_lower_defaults(
    declared: Path, tmp_path: Path, fleet: Fleet, step_path: str
) -> None:
    """Both servers default to 1 MiB; the 2 MB the channel declares raises theirs and lowers
    the run's (64 MiB) to what is declared."""
    serve_declared(fleet, Camera(FRAME, maximum=2_000_000), 2_000_000, limit=MIB)
    out = tmp_path / "out"
    code, err, summary = run(
        declared, out, step_path, "--output-variables", "Viewer.*", "--record", "Camera"
    )
    assert code == 0, err
    assert summary["status"] == "completed"
    assert summary["steps"] == 4
    sizes = [row["Viewer.size"] for row in Coupler.results(out)]
    assert sizes == ["0", "0", str(FRAME), str(FRAME), str(FRAME)]  # Jacobi: a step later
    recorded = recording.read(out / "recordings" / "Camera.crec").description
    assert recorded.channel("frame").max_bytes == 2_000_000  # type: ignore[union-attr]
    replayed = asyncio.run(described(ReplayParticipant(out, "Camera")))  # declares the same
    assert replayed.channel("frame").max_bytes == 2_000_000  # type: ignore[union-attr]


def test_an_output_declaring_more_than_its_input_accepts_is_refused(
    declared: Path, tmp_path: Path, fleet: Fleet
) -> None:
    serve_declared(fleet, Camera(FRAME, maximum=2_000_000), 1_500_000)
    expected = (
        "connection Camera.frame -> Viewer.frame: 'Camera.frame' declares values of up to "
        "2000000 bytes, but 'Viewer.frame' accepts at most 1500000 bytes (max_bytes); connect "
        "an input that accepts 2000000 bytes, or have the output's participant send (and "
        "declare) at most 1500000"
    )
    line = next(
        n
        for n, text in enumerate(declared.read_text().splitlines(), start=1)
        if "<ssd:Connection " in text
    )
    for command in (("validate",), ("run", "--out", tmp_path / "run")):
        outcome = Coupler.process(*command[:1], declared, *command[1:])
        assert outcome.code == 1, outcome.err
        assert f"declared.ssd line {line}: {expected}" in outcome.err
        assert "Traceback" not in outcome.err
    assert not (tmp_path / "run" / "results.csv").exists()


def test_a_frame_over_its_declared_maximum_fails_the_run_keeping_the_rows(
    declared: Path, tmp_path: Path, fleet: Fleet, step_path: str
) -> None:
    """The camera declares 1.5 MB and sends 1.6 MB at its third step: its server refuses to
    send it, and the run fails naming the channel, the size and the maximum."""
    camera = Camera(FRAME, maximum=1_500_000, larger=1_600_000, larger_from=3)
    serve_declared(fleet, camera, 2_000_000)
    code, err, summary = run(
        declared, tmp_path / "out", step_path, "--output-variables", "Viewer.*"
    )
    assert code == 1, err
    expected = (
        "Camera.DoStep [RESOURCE_EXHAUSTED]: output 'frame' carries 1600000 bytes, over its "
        "declared maximum of 1500000 bytes (max_bytes)"
    )
    assert expected in err
    assert "Traceback" not in err
    assert summary["status"] == "failed"
    assert expected in summary["reason"]
    rows = Coupler.results(tmp_path / "out")
    assert [row["time"] for row in rows] == ["0.0", "0.1", "0.2"]


def feedthrough3_sized(fmus: dict[str, Path], folder: Path, variable: str, size: int) -> Path:
    """The Feedthrough3 FMU with ``maxSize`` given to its Binary ``variable`` (written into
    ``folder``)."""
    sized = folder / "Feedthrough3.fmu"
    with zipfile.ZipFile(fmus["Feedthrough3"]) as source, zipfile.ZipFile(sized, "w") as copy:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                name = f'<Binary name="{variable}"'.encode()
                assert name in data, f"Feedthrough3 has no Binary {variable}"
                data = data.replace(name, f'<Binary maxSize="{size}" name="{variable}"'.encode())
            copy.writestr(item, data)
    return sized


def test_an_fmus_binary_max_size_is_declared_and_kept(
    tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """FMI 3's ``maxSize`` of a Binary variable is the channel's declared maximum: an
    in-process FMU whose output is over it fails the run naming it."""
    sized = feedthrough3_sized(fmus, tmp_path, "binary_out", 4)
    channel = asyncio.run(described(FmuParticipant(sized))).channel("binary_out")
    assert channel is not None and channel.max_bytes == 4
    fits = Coupler.process(
        "run",
        sized,
        "--stop-time",
        "0.2",
        "--step",
        "0.1",
        "--param",
        "binary_in=01020304",
        "--out",
        tmp_path / "fits",
    )
    assert fits.code == 0, fits.err
    over = Coupler.process(
        "run",
        sized,
        "--stop-time",
        "0.2",
        "--step",
        "0.1",
        "--param",
        "binary_in=0102030405",
        "--out",
        tmp_path / "over",
    )
    assert over.code == 1, over.err
    assert (
        "Feedthrough.Initialize [RESOURCE_EXHAUSTED]: output Feedthrough.binary_out carries 5 "
        "bytes, over its declared maximum of 4 bytes (max_bytes)"
    ) in over.err


def test_declarations_over_the_runs_limit_are_warned_about_and_capped(
    declared: Path, tmp_path: Path, fleet: Fleet, step_path: str
) -> None:
    """--max-message-size caps what participants declare: 2 MB declared, 1 MiB allowed, a
    1.44 MB frame fails the run naming the channel and the way to raise the cap, which the
    checks warned about before the run."""
    serve_declared(fleet, Camera(FRAME, maximum=2_000_000), 2_000_000)
    code, err, summary = run(declared, tmp_path / "out", step_path, "--max-message-size", "1")
    assert code == 1, err
    assert (
        "Camera.DoStep [RESOURCE_EXHAUSTED]: output Camera.frame carries 1440000 bytes: over the "
        "message limit of 1048576 bytes (1 MiB); raise the limit"
    ) in err
    assert (
        "participant 'Camera' declares outputs of up to 2000000 bytes together, more than the "
        "run's message limit of 1048576 bytes (1 MiB): a step carrying more fails the run; "
        "raise --max-message-size to 2"
    ) in " ".join(summary["warnings"])


def test_an_in_process_fmus_binary_input_over_its_max_size_fails_naming_it(
    tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """An in-process FMU is promised at most ``maxSize`` bytes for a Binary input: a longer
    value fails the run naming the input, its size and its maximum, before the FMU sees it."""
    sized = feedthrough3_sized(fmus, tmp_path, "binary_in", 4)
    channel = asyncio.run(described(FmuParticipant(sized))).channel("binary_in")
    assert channel is not None and channel.max_bytes == 4
    run = ["run", sized, "--stop-time", "0.2", "--step", "0.1"]
    fits = Coupler.process(*run, "--param", "binary_in=01020304", "--out", tmp_path / "fits")
    assert fits.code == 0, fits.err
    over = Coupler.process(*run, "--param", "binary_in=0102030405", "--out", tmp_path / "over")
    assert over.code == 1, over.err
    assert "input Feedthrough.binary_in carries 5 bytes, over its declared maximum of 4" in over.err
    assert "Traceback" not in over.err
