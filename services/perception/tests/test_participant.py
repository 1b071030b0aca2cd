"""The perception participant over gRPC: frames in, BaliseDetections out.

test --Image + TrainState--> RemoteParticipant --gRPC--> ParticipantServer(perception)
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from coupler.channels import Causality, RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError
from coupler.messages import decode_message
from coupler.v1.sensors_pb2 import Image
from coupler_railway import Infrastructure
from coupler_railway.messages import BALISE_DETECTIONS, IMAGE, TRAIN_STATE
from openrails_mock.renderer import Renderer

from .conftest import frame, state

OFFSET = 41.7  # the camera's place on the line when the train has travelled 0 m


async def test_describe(perception: RemoteParticipant) -> None:
    description = await perception.describe()
    assert [c.name for c in description.of(Causality.INPUT)] == ["image", "train_state"]
    assert description.channel("image").message_type == IMAGE  # type: ignore[union-attr]
    assert description.channel("train_state").message_type == TRAIN_STATE  # type: ignore[union-attr]
    # the largest frame it takes (4K UHD, rgb8) and a train state, declared: the run's limits
    # and its server's follow (docs/protocol.md "Message size")
    maxima = {c.name: c.max_bytes for c in description.of(Causality.INPUT)}
    assert maxima == {"image": 256 + 3840 * 2160 * 3, "train_state": 128}
    assert [c.name for c in description.of(Causality.OUTPUT)] == ["detections", "detection_count"]
    assert description.channel("detections").message_type == BALISE_DETECTIONS  # type: ignore[union-attr]


async def test_detections_carry_box_distance_and_track_position(
    perception: RemoteParticipant, renderer: Renderer, test_line: Infrastructure
) -> None:
    travelled = 40.0
    front = OFFSET + travelled  # balises 101, 102 at 100 and 103 m: 18.3 and 21.3 m ahead
    first = await perception.initialize(
        RunSetup(run_id="p", start_time=0.0, step_size=0.2, parameters={"track_offset": OFFSET})
    )
    assert first["detection_count"] == 0  # no frame yet
    out = await perception.do_step(
        1.0, 0.2, {"image": frame(renderer, front, 1.2), "train_state": state(travelled, 1.2)}
    )
    await perception.terminate()
    assert out["detection_count"] == 2
    message = decode_message(BALISE_DETECTIONS, out["detections"])  # type: ignore[arg-type]
    assert message["time_s"] == 1.2 and message["sensor"] == "front"
    truth = [b.distance_m for b in test_line.balises if b.code in (101, 102)]
    for detection, balise in zip(message["detections"], truth, strict=True):
        assert detection["time_s"] == 1.2
        assert detection["track_position_m"] == pytest.approx(balise, abs=0.5)
        assert detection["distance_ahead_m"] == pytest.approx(balise - front, abs=0.5)
        box = detection["box"]
        assert box["left"] <= box["right"] and box["top"] <= box["bottom"]
        assert 0.0 < detection["confidence"] <= 1.0


async def test_a_depth_frame_or_a_frame_of_the_wrong_size_is_refused_naming_the_channel(
    perception: RemoteParticipant, renderer: Renderer
) -> None:
    await perception.initialize(RunSetup(run_id="p", start_time=0.0, step_size=0.2))
    depth = Image(sensor="lidar", encoding="depth16-class-id", width=2, height=1, data=b"\0" * 12)
    with pytest.raises(ParticipantError) as caught:
        await perception.do_step(0.0, 0.2, {"image": depth.SerializeToString()})
    assert caught.value.status == "INVALID_ARGUMENT"
    assert "channel 'image' carries a 'depth16-class-id' frame of sensor 'lidar'" in str(
        caught.value
    )
    short = Image()
    short.ParseFromString(frame(renderer, 100.0))
    short.data = short.data[:-3]
    await perception.initialize(RunSetup(run_id="q", start_time=0.0, step_size=0.2))
    with pytest.raises(ParticipantError) as caught:
        await perception.do_step(0.0, 0.2, {"image": short.SerializeToString()})
    assert caught.value.status == "INVALID_ARGUMENT"
    assert "sensor 'front' declares 800 x 600 rgb8 (1440000 bytes) but its data has 1439997" in (
        str(caught.value)
    )


def test_the_service_starts_and_answers_describe() -> None:
    with subprocess.Popen(
        [sys.executable, "-m", "perception", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as process:
        try:
            assert process.stdout is not None
            line = process.stdout.readline()
            assert line.startswith("perception listening at grpc://127.0.0.1:")
            address = line.split(" at ", 1)[1].strip()
            described = subprocess.run(
                [sys.executable, "-m", "coupler_orchestrator", "describe", address],
                capture_output=True,
                text=True,
                timeout=60,
            )
        finally:
            process.terminate()
    assert described.returncode == 0, described.stderr
    assert "detections" in described.stdout and "coupler.v1.BaliseDetections" in described.stdout
    assert "Binary(coupler.v1.Image) max 24883456 B" in described.stdout  # 4K UHD, rgb8
