"""OpenRails' camera and depth sensors through the bridge: one Binary channel per sensor,
and the labels of each colour camera's frames beside it.

    sensors.json --> openrails_mock (renders the frames)
    sensors.json --> bridge: Describe lists `front`, `front_labels` and `lidar`
    RemoteParticipant --gRPC--> bridge --GET /API/CAMERASENSOR/<name>[/LABELS]--> mock
    RemoteParticipant --Initialize(weather=snow, ...)--> bridge --POST /API/RESET--> mock

The frames arrive unchanged (byte for byte what the mock serves for that state), wrapped in
an Image with the size, encoding and intrinsics of the sensor. What the mock cannot do (a
frame of the wrong size, a sensor OpenRails does not have) comes from a tiny OpenRails.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from fractions import Fraction
from pathlib import Path
from typing import Any

import aiohttp
import pytest
from aiohttp import web

from coupler.channels import Causality, RunSetup, ValueType
from coupler.errors import ParticipantError, ScenarioError
from coupler.messages import decode_message
from coupler.v1.railway_pb2 import TrainState
from coupler.v1.sensors_pb2 import FrameLabels, Image, ObjectClass
from coupler_railway.messages import FRAME_LABELS, IMAGE
from openrails_bridge.__main__ import build
from openrails_bridge.config import BridgeSettings

from .support import RANGES, Bridge, Mock, serve_app, step_reply

ROOT = Path(__file__).resolve().parents[3]
TEST_LINE = ROOT / "packages/railway/tests/data/test-line.railml"
SENSORS = [
    {"sensorName": "front", "sensorType": "rgb", "trainName": "PLAYER", "width": 800,
     "height": 600, "fov": 45.0},
    {"sensorName": "lidar", "sensorType": "depth", "trainName": "PLAYER", "width": 200,
     "height": 150, "fov": 45.0, "range": 200.0},
]  # fmt: skip


@pytest.fixture
def sensors(tmp_path: Path) -> Path:
    path = tmp_path / "sensors.json"
    path.write_text(json.dumps(SENSORS))
    return path


def image(data: bytes) -> Image:
    message = Image()
    message.ParseFromString(data)
    return message


async def test_describe_offers_one_image_channel_per_sensor(
    mock: Mock, bridge: Bridge, sensors: Path
) -> None:
    async with mock(sensors=sensors) as url, bridge(url, sensors=sensors) as remote:
        description = await remote.describe()
        received = remote.limits.received
    outputs = description.of(Causality.OUTPUT)
    assert [c.name for c in outputs][-3:] == ["front", "front_labels", "lidar"]
    for name in ("front", "lidar"):
        channel = description.channel(name)
        assert channel is not None
        assert channel.type is ValueType.BINARY and channel.message_type == IMAGE
    assert "800 x 600, rgb8" in description.channel("front").description  # type: ignore[union-attr]
    # the largest frame of each: the Image's other fields and width * height pixels, declared
    # and a train state, so the run's limit towards the bridge is theirs, not the default
    maxima = {c.name: c.max_bytes for c in outputs if c.sized}
    assert maxima == {
        "train_state": 128,
        "front": 256 + 800 * 600 * 3,
        "front_labels": 256 * 1024,  # the ground truth beside the colour camera
        "lidar": 256 + 200 * 150 * 6,
    }
    assert received == sum(maxima.values())  # what its client lets through (plus framing)


async def test_frames_arrive_unchanged_in_images(mock: Mock, bridge: Bridge, sensors: Path) -> None:
    config = {"sensors": sensors, "railml": TEST_LINE, "start_distance_m": 75.0}
    async with mock(**config) as url, bridge(url, sensors=sensors) as remote:
        first = await remote.initialize(
            RunSetup(run_id="s", start_time=0.0, step_size=0.4, inputs={"throttle": 1.0})
        )
        outputs = [await remote.do_step(0.4 * k, 0.4, {}) for k in range(3)]
        async with aiohttp.ClientSession(url) as http:
            served = {}
            for name in ("front", "lidar"):
                async with http.get(f"/API/CAMERASENSOR/{name}") as resp:
                    served[name] = await resp.read()
        await remote.terminate()

    start = image(first["front"])
    assert (start.width, start.height, start.encoding, start.time_s) == (800, 600, "rgb8", 0.0)
    assert len(start.data) == 1_440_000  # a 1.44 MB frame through gRPC
    front, lidar = image(outputs[-1]["front"]), image(outputs[-1]["lidar"])
    assert front.data == served["front"] and lidar.data == served["lidar"]
    assert front.data != start.data  # the train moved
    assert front.time_s == pytest.approx(1.2) and front.sensor == "front"
    assert lidar.encoding == "depth16-class-id" and lidar.max_distance_m == 200.0
    assert (lidar.width, lidar.height) == (200, 150)
    # fov 45 degrees vertical: fy = 300 / tan(22.5 deg); square pixels
    assert front.intrinsics.fy == pytest.approx(724.2640687, rel=1e-6)
    assert front.intrinsics.fx == pytest.approx(front.intrinsics.fy)
    assert (front.intrinsics.cx, front.intrinsics.cy) == (399.5, 299.5)
    fields = decode_message(IMAGE, outputs[-1]["lidar"])
    assert fields["intrinsics"]["fy"] == pytest.approx(75 / 0.41421356, rel=1e-6)


async def test_every_frame_and_train_state_carries_its_time_on_the_runs_grid(
    mock: Mock, bridge: Bridge, sensors: Path
) -> None:
    """A stretch of 0.4 s steps from t0 = 0.2 as the orchestrator sends them (each start the
    grid's own double): the Image, FrameLabels and TrainState of each step say its end as the
    grid has it -- 0.6, never 0.2 + 0.4 = 0.6000000000000001 (issue 45 item 4)."""
    grid = [float(Fraction(1, 5) + k * Fraction(2, 5)) for k in range(5)]  # 0.2 .. 1.8
    config = {"sensors": sensors, "railml": TEST_LINE, "start_distance_m": 75.0}
    async with mock(**config) as url, bridge(url, sensors=sensors) as remote:
        await remote.initialize(
            RunSetup(run_id="g", start_time=0.2, step_size=0.4, inputs={"throttle": 1.0})
        )
        outputs = [await remote.do_step(t, 0.4, {}) for t in grid[:-1]]
        await remote.terminate()
    drifting = [a + 0.4 for a in grid[:-1]]
    assert drifting != grid[1:]  # binary sums leave the grid on this stretch
    for end, out in zip(grid[1:], outputs, strict=True):
        labels, state = FrameLabels(), TrainState()
        labels.ParseFromString(out["front_labels"])
        state.ParseFromString(out["train_state"])
        times = [image(out["front"]).time_s, image(out["lidar"]).time_s]
        times += [labels.time_s, state.time_s]
        assert times == [end] * 4, (end, times)
        assert all(len(repr(t)) <= 3 for t in times)  # 0.6, 1.4, ...: as the user wrote them


async def test_a_sensor_openrails_does_not_have_fails_initialize_naming_it(
    mock: Mock, bridge: Bridge, sensors: Path, tmp_path: Path
) -> None:
    only_front = tmp_path / "front.json"
    only_front.write_text(json.dumps(SENSORS[:1]))
    async with mock(sensors=only_front) as url, bridge(url, sensors=sensors) as remote:
        with pytest.raises(ParticipantError) as caught:
            await remote.initialize(RunSetup(run_id="x", start_time=0.0, step_size=0.2))
    assert caught.value.status == "UNAVAILABLE"
    assert "has no camera sensor 'lidar' (its step reply's CameraSensors: ['front'])" in str(
        caught.value
    )
    assert "OPENRAILS_BRIDGE_SENSORS" in str(caught.value)


def tiny_with_sensor(
    frame: bytes, declared: dict[str, Any] | None, status: int = 200, pieces: int = 0
) -> web.Application:
    """OpenRails whose step reply declares one 4 x 3 RGB sensor ``cam`` (or ``declared``)
    and whose GET of its frame answers ``frame`` (in ``pieces`` HTTP chunks of unannounced
    length, when given)."""

    async def ready(request: web.Request) -> web.Response:
        return web.Response(status=200)

    async def cabcontrols(request: web.Request) -> web.Response:
        return web.json_response(RANGES)

    async def step(request: web.Request) -> web.Response:
        reply = step_reply()
        reply["CameraSensors"] = {
            "cam": declared or {"width": 4, "height": 3, "h_scale": 1.0, "v_scale": 1.3}
        }
        return web.json_response(reply)

    async def map_(request: web.Request) -> web.Response:
        return web.json_response({"LatLon": {"Lat": 50.5, "Lon": 13.0}, "DirectionDeg": 90.0})

    async def display(request: web.Request) -> web.Response:
        return web.json_response([{"FirstCol": "Speed", "LastCol": "0.0 km/h"}])

    async def camera(request: web.Request) -> web.StreamResponse:
        if not pieces:
            return web.Response(body=frame, status=status, content_type="application/octet-stream")
        response = web.StreamResponse(status=status)
        response.enable_chunked_encoding()
        await response.prepare(request)
        size = -(-len(frame) // pieces)
        for at in range(0, len(frame), size):
            await response.write(frame[at : at + size])
            await asyncio.sleep(0.01)  # apart: the bridge reads them as they come
        await response.write_eof()
        return response

    app = web.Application()
    app.router.add_get("/API/READY", ready)
    app.router.add_get("/API/CABCONTROLS", cabcontrols)
    app.router.add_post("/API/CABCONTROLS", step)
    app.router.add_get("/API/MAP", map_)
    app.router.add_get("/API/TRAINDRIVINGDISPLAY", display)
    app.router.add_get("/API/CAMERASENSOR/cam", camera)
    return app


@pytest.mark.parametrize(
    ("frame", "declared", "status", "message", "pieces"),
    [
        (b"\x01" * 35, None, 200, "answered a frame of 35 bytes, but CameraSensors declares "
                                  "sensor 'cam' 4 x 3 rgb: 36 bytes", 0),
        (b"\x01" * 5000, None, 200, "with 5000 bytes, more than the 36 bytes CameraSensors "
                                    "declares for sensor 'cam' (4 x 3 rgb); refused unread", 0),
        (b"{}", None, 404, "/API/CAMERASENSOR/cam answered 404 to GET", 0),
        (b"", {"width": 8, "height": 3, "h_scale": 1.0, "v_scale": 1.3}, 200,
         "describes camera sensor 'cam' as 8 x 3, but", 0),
        (b"\x01" * 35, None, 200, "answered a frame of 35 bytes, but CameraSensors declares "
                                  "sensor 'cam' 4 x 3 rgb: 36 bytes", 3),
        (b"\x01" * 60, None, 200, "with more than the 36 bytes CameraSensors declares for "
                                  "sensor 'cam' (4 x 3 rgb); refused after", 3),
    ],
)  # fmt: skip
async def test_a_frame_that_does_not_match_its_declared_size_is_an_error_naming_it(
    bridge: Bridge,
    tmp_path: Path,
    frame: bytes,
    declared: dict[str, Any] | None,
    status: int,
    message: str,
    pieces: int,
) -> None:
    """Announced (Content-Length) or not (chunked, ``pieces``)."""
    path = tmp_path / "cam.json"
    path.write_text(
        json.dumps([{"sensorName": "cam", "sensorType": "rgb", "width": 4, "height": 3}])
    )
    tiny = tiny_with_sensor(frame, declared, status, pieces)
    async with serve_app(tiny) as url, bridge(url, sensors=path) as remote:
        await remote.initialize(RunSetup(run_id="x", start_time=0.0, step_size=0.2))
        with pytest.raises(ParticipantError) as caught:
            await remote.do_step(0.0, 0.2, {})
    assert caught.value.status == "UNAVAILABLE"
    assert message in str(caught.value)


async def test_a_frame_in_pieces_arrives_whole_in_its_image(bridge: Bridge, tmp_path: Path) -> None:
    """A frame whose HTTP answer comes in pieces (chunked, its length unannounced) is the
    Image's data byte for byte, the pieces joined once behind the Image's other fields."""
    path = tmp_path / "cam.json"
    path.write_text(
        json.dumps([{"sensorName": "cam", "sensorType": "rgb", "width": 4, "height": 3}])
    )
    frame = bytes(range(36))
    async with (
        serve_app(tiny_with_sensor(frame, None, pieces=4)) as url,
        bridge(url, sensors=path) as remote,
    ):
        await remote.initialize(RunSetup(run_id="x", start_time=0.0, step_size=0.2))
        out = await remote.do_step(0.0, 0.2, {})
    cam = image(out["cam"])
    assert cam.data == frame and (cam.width, cam.height, cam.time_s) == (4, 3, 0.2)
    whole = Image()
    whole.CopyFrom(cam)
    assert out["cam"] == whole.SerializeToString(deterministic=True)  # as protobuf writes it


def test_bad_sensor_files_are_refused_naming_the_entry(tmp_path: Path) -> None:
    cases = [
        ([{"sensorName": "cam", "sensorType": "thermal", "width": 4, "height": 3}],
         "sensor 0 ('cam'): unknown sensorType 'thermal'; the sensor types are 'rgb' and"),
        ([{"sensorName": "cam", "sensorType": "rgb", "width": 0, "height": 3}],
         "width and height must be positive whole numbers of pixels, got 0 x 3"),
        ([{"sensorName": "speed", "sensorType": "rgb", "width": 4, "height": 3}],
         "sensor 'speed' would be a channel of the same name"),
        ({"sensorName": "cam"}, "must be a JSON list of sensors"),
    ]  # fmt: skip
    for entries, message in cases:
        path = tmp_path / "s.json"
        path.write_text(json.dumps(entries))
        with pytest.raises(ScenarioError) as caught:
            build(BridgeSettings(sensors=path))
        assert message in str(caught.value)
    path = tmp_path / "ok.json"
    path.write_text(json.dumps(SENSORS))
    with pytest.raises(ScenarioError, match="use --mode lockstep"):
        build(BridgeSettings(sensors=path, mode="stock"))


def test_the_bridge_process_refuses_a_bad_sensor_file_without_a_traceback(
    tmp_path: Path,
) -> None:
    path = tmp_path / "s.json"
    path.write_text("[{\n")
    done = subprocess.run(
        [sys.executable, "-m", "openrails_bridge", "--port", "0", "--sensors", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1
    assert f"openrails-bridge: {path}:2: the sensor configuration is not valid JSON" in done.stderr
    assert "Traceback" not in done.stderr


async def test_labels_ride_beside_the_camera_for_the_same_frame(
    mock: Mock, bridge: Bridge, sensors: Path
) -> None:
    config = {"sensors": sensors, "railml": TEST_LINE, "start_distance_m": 75.0}
    async with mock(**config) as url, bridge(url, sensors=sensors) as remote:
        description = await remote.describe()
        first = await remote.initialize(RunSetup(run_id="l", start_time=0.0, step_size=0.4))
        outputs = await remote.do_step(0.0, 0.4, {})
        async with aiohttp.ClientSession(url) as http:
            async with http.get("/API/CAMERASENSOR/front/LABELS") as resp:
                served = await resp.json()
            async with http.get("/API/CAMERASENSOR/lidar/LABELS") as resp:
                assert resp.status == 404  # labels are the colour cameras'
        await remote.terminate()
    channel = description.channel("front_labels")
    assert channel is not None and channel.message_type == FRAME_LABELS
    assert "lidar_labels" not in [c.name for c in description.channels]
    for answer in (first, outputs):
        labels = FrameLabels()
        labels.ParseFromString(answer["front_labels"])
        assert (labels.sensor, labels.width, labels.height) == ("front", 800, 600)
        balises = {
            o.id: o for o in labels.objects if o.object_class == ObjectClass.OBJECT_CLASS_BALISE
        }
        assert {101, 102} <= set(balises)  # the group 45 m ahead of the camera at 75 m
    assert labels.time_s == pytest.approx(0.4)
    mine = {(o["class"], o["id"]): o for o in served["objects"]}
    for o in labels.objects:
        their = mine[("balise" if o.object_class == ObjectClass.OBJECT_CLASS_BALISE else
                      "signal" if o.object_class == ObjectClass.OBJECT_CLASS_SIGNAL else
                      "platform_edge", o.id)]  # fmt: skip
        assert (o.pixels, o.unoccluded_pixels) == (their["pixels"], their["unoccludedPixels"])
        if o.pixels:
            assert [o.box.left, o.box.top, o.box.right, o.box.bottom] == their["box"]
        assert o.visible_fraction == pytest.approx(their["visibleFraction"])


async def test_the_runs_environment_reaches_the_simulator_at_initialize(
    mock: Mock, bridge: Bridge, sensors: Path
) -> None:
    """The OpenRails participant's parameters set the world of the run (POST /API/RESET with
    an Environment); a run without them (or with empty Strings, what an FMI master such as the
    exported FMU gives them) gets the world the simulator was started with."""
    async with mock(sensors=sensors) as url, bridge(url, sensors=sensors) as remote:

        async def environment() -> dict[str, Any]:
            async with aiohttp.ClientSession(url) as http, http.get("/API/ENVIRONMENT") as resp:
                found: dict[str, Any] = await resp.json()
                return found

        parameters = {
            "weather": "snow",
            "season": "3",
            "time_of_day": 61200.0,
            "visibility": 120.0,
            "conditions": '{"noise": true, "dirt": 0.2}',
        }
        await remote.initialize(
            RunSetup(run_id="e", start_time=0.0, step_size=0.2, parameters=parameters)
        )
        world = await environment()
        await remote.terminate()
        unset = {"season": "", "weather": "", "light": "", "conditions": ""}  # an FMI master's
        await remote.initialize(
            RunSetup(run_id="f", start_time=0.0, step_size=0.2, parameters=unset)
        )
        plain = await environment()
        await remote.terminate()
        with pytest.raises(ParticipantError) as caught:
            await remote.initialize(
                RunSetup(run_id="g", start_time=0.0, step_size=0.2, parameters={"weather": "hail"})
            )
    conditions = world["conditions"]
    assert (conditions["weather"], conditions["season"], conditions["light"]) == (
        "snow", "winter", "sun")  # fmt: skip
    assert conditions["visibility_m"] == 120.0 and conditions["noise"] is True
    assert conditions["dirt"] == 0.2
    assert world["time"] == 61200.0  # 17:00, the clock at the run's start
    assert plain["conditions"]["weather"] == "clear" and plain["time"] == 8 * 3600.0
    assert "weather must be one of clear (0), snow (1), rain (2), got 'hail'" in str(caught.value)
