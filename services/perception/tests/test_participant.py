"""The perception participant over gRPC: frames in, BaliseDetections out.

test --Image + TrainState--> RemoteParticipant --gRPC--> ParticipantServer(perception)
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from coupler.channels import Causality, RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError
from coupler.messages import decode_message
from coupler.v1.sensors_pb2 import CameraIntrinsics, Image
from coupler_railway import Infrastructure
from coupler_railway.messages import BALISE_DETECTIONS, IMAGE, TRAIN_STATE
from openrails_mock.renderer import Renderer
from perception.detector import MAX_DETECTIONS

from .support import frame, state

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


@pytest.mark.parametrize(
    ("fx", "fy", "shown"),
    [
        (math.nan, math.nan, "fx=nan, fy=nan"),
        (0.0, 0.0, "fx=0.0, fy=0.0"),
        (724.3, -724.3, "fy=-724.3"),
        (math.inf, 724.3, "fx=inf"),
    ],
)
async def test_intrinsics_no_camera_has_are_refused_naming_the_channel(
    perception: RemoteParticipant, renderer: Renderer, fx: float, fy: float, shown: str
) -> None:
    """NaN focal lengths gave an "OK" detection at a NaN distance, fx=0 an INTERNAL
    ZeroDivisionError (issue 37)."""
    image = Image()
    image.ParseFromString(frame(renderer, 80.0))  # balises 101, 102 in sight
    image.intrinsics.fx, image.intrinsics.fy = fx, fy
    await perception.initialize(RunSetup(run_id="p", start_time=0.0, step_size=0.2))
    with pytest.raises(ParticipantError) as caught:
        await perception.do_step(0.0, 0.2, {"image": image.SerializeToString()})
    assert caught.value.status == "INVALID_ARGUMENT"
    assert "channel 'image': sensor 'front' has intrinsics" in str(caught.value)
    assert shown in str(caught.value)


@pytest.mark.parametrize("channel", ["image", "train_state"])
async def test_bytes_that_are_no_message_are_invalid_argument_naming_the_channel(
    perception: RemoteParticipant, renderer: Renderer, channel: str
) -> None:
    garbage = bytes(range(100))  # field 0, wire type 0: protobuf cannot parse it
    inputs = {"image": frame(renderer, 80.0), channel: garbage}
    await perception.initialize(RunSetup(run_id="p", start_time=0.0, step_size=0.2))
    with pytest.raises(ParticipantError) as caught:
        await perception.do_step(0.0, 0.2, inputs)
    assert caught.value.status == "INVALID_ARGUMENT"  # was INTERNAL (a DecodeError)
    assert f"channel '{channel}' carries 100 bytes that are not a coupler.v1." in str(caught.value)


def confetti(width: int = 3840, height: int = 2160) -> bytes:
    """A legal 4K frame whose ground is covered by 2-pixel yellow dots, 3 pixels apart."""
    pixels = np.full((height, width, 3), 110, dtype=np.uint8)
    ground = pixels[height // 2 + 100 :]
    ground[::3, 0::3] = ground[::3, 1::3] = (236, 196, 24)
    focal = height / 2 / math.tan(math.radians(22.5))
    return Image(
        sensor="front",
        time_s=0.4,
        width=width,
        height=height,
        encoding="rgb8",
        intrinsics=CameraIntrinsics(fx=focal, fy=focal, cx=width / 2 - 0.5, cy=height / 2 - 0.5),
        data=pixels.tobytes(),
    ).SerializeToString()


async def test_a_frame_of_yellow_confetti_gives_a_bounded_answer_that_says_so(
    perception: RemoteParticipant,
) -> None:
    """Hundreds of thousands of 2-pixel blobs were hundreds of thousands of detections (a 35 MB
    answer, issue 37): the nearest ``max_detections`` are reported, ``omitted`` the rest."""
    await perception.initialize(RunSetup(run_id="p", start_time=0.0, step_size=0.4))
    out = await perception.do_step(0.0, 0.4, {"image": confetti()})
    await perception.terminate()
    message = decode_message(BALISE_DETECTIONS, out["detections"])  # type: ignore[arg-type]
    assert out["detection_count"] == len(message["detections"]) == MAX_DETECTIONS
    assert message["omitted"] > 100_000
    assert len(out["detections"]) < 10_000  # type: ignore[arg-type]
    distances = [d["distance_ahead_m"] for d in message["detections"]]
    assert distances == sorted(distances) and distances[-1] < 40.0  # the nearest ones


async def test_max_detections_out_of_its_range_is_refused(perception: RemoteParticipant) -> None:
    with pytest.raises(ParticipantError) as caught:
        await perception.initialize(
            RunSetup(run_id="p", start_time=0.0, step_size=0.4, parameters={"max_detections": 0})
        )
    assert caught.value.status == "INVALID_ARGUMENT"
    assert "parameter 'max_detections' is 0" in str(caught.value)
