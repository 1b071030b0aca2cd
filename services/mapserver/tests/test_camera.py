"""The camera panel: frames (coupler.v1.Image) and detections (coupler.v1.BaliseDetections)
through the real gRPC wire to the map, out as SSE events, JPEG and, in Chromium, a picture with
its boxes next to the balise table.

    Run (RemoteParticipant) --camera, detections--> map server --SSE, /api/frame.jpg--> browser

The frames here are drawn by the test (a grey ground, a yellow block where the detection box
says); tests/e2e/test_railway_perception.py shows the real chain's frames.
"""

from __future__ import annotations

import io
from typing import Any

import aiohttp
import numpy as np
import pytest
from PIL import Image as PillowImage

from coupler.v1.railway_pb2 import BaliseDetection, BaliseDetections, PixelBox
from coupler.v1.sensors_pb2 import Image
from coupler_dev.browser import CHROMIUM, NO_CHROMIUM
from mapserver.camera import CameraView

from .support import REPO, EventStream, MapService, Run, page_errors

ARTIFACT = REPO / "test-artifacts" / "mapserver-camera.png"
BOX = (380, 400, 420, 410)  # left, top, right, bottom


def frame(time_s: float, width: int = 800, height: int = 600) -> bytes:
    pixels = np.full((height, width, 3), 110, dtype=np.uint8)
    pixels[: height // 2] = (150, 180, 220)  # sky
    left, top, right, bottom = BOX
    pixels[top : bottom + 1, left : right + 1] = (236, 196, 24)
    return Image(
        sensor="front",
        time_s=time_s,
        width=width,
        height=height,
        encoding="rgb8",
        data=pixels.tobytes(),
    ).SerializeToString()


def seen(time_s: float, *boxes: tuple[int, int, int, int]) -> bytes:
    return BaliseDetections(
        time_s=time_s,
        sensor="front",
        detections=[
            BaliseDetection(
                time_s=time_s,
                box=PixelBox(left=b[0], top=b[1], right=b[2], bottom=b[3]),
                distance_ahead_m=21.5,
                track_position_m=100.0,
                confidence=0.9,
            )
            for b in boxes
        ],
    ).SerializeToString()


def with_camera(run: Run) -> Any:
    """Inputs of each step: the frame of the step's time and the detections of the frame
    before (a perception participant answers a step late)."""

    def add(values: dict[str, Any]) -> dict[str, Any]:
        values["camera"] = frame(run.time_s)
        if run.time_s >= run.step_s:
            values["detections"] = seen(run.time_s - run.step_s, BOX)
        return values

    return add


async def test_frames_and_boxes_in_events_and_jpeg(service: MapService, run: Run) -> None:
    async with aiohttp.ClientSession() as http:
        async with http.get(service.url + "api/frame.jpg") as resp:
            assert resp.status == 404
            assert "no camera frame yet" in (await resp.json())["error"]
        async with http.get(service.url + "api/events") as resp:
            stream = EventStream(resp)
            await stream.next()  # the snapshot
            await run.start()
            await run.steps(3, inputs=with_camera(run))
            events = await stream.until(
                lambda e: e["type"] == "step" and (e.get("camera") or {}).get("frame") == 2
            )
        camera = events[-1]["camera"]
        # frames at t = 0, 1, 2 arrived; the detections of t = 1 came with the frame of t = 2:
        # the panel shows frame 2 (t = 1) with its box
        assert camera["time_s"] == 1.0 and camera["judged"] is True
        assert (camera["width"], camera["height"], camera["sensor"]) == (800, 600, "front")
        assert camera["detections"] == [
            {"left": 380, "top": 400, "right": 420, "bottom": 410, "distance_ahead_m": 21.5,
             "track_position_m": 100.0, "confidence": 0.9}
        ]  # fmt: skip
        async with http.get(service.url + f"api/frame.jpg?n={camera['frame']}") as resp:
            assert resp.status == 200 and resp.content_type == "image/jpeg"
            picture = np.asarray(PillowImage.open(io.BytesIO(await resp.read())))
    assert picture.shape == (600, 800, 3)
    block = picture[402:409, 385:416].reshape(-1, 3).mean(axis=0)
    assert block[0] > 200 and block[1] > 160 and block[2] < 80  # still yellow after JPEG


def test_a_frame_is_kept_as_it_came_and_pictured_when_asked() -> None:
    """A step reads only a frame's header: the pixels stay a view of the bytes the step
    brought; the JPEG is made when asked, once, and shows those pixels (also when the Image's
    ``data`` is not its last field, or is written twice: protobuf's reading)."""
    view = CameraView()
    data = frame(0.5)
    assert view.update({"camera": data})
    shown = view.shown()
    assert shown is not None and shown.pixels.obj is data  # not a copy
    assert view.jpeg() is view.jpeg()  # encoded once
    picture = np.asarray(PillowImage.open(io.BytesIO(view.jpeg() or b"")))
    left, top, right, bottom = BOX
    assert picture[top + 2 : bottom - 1, left + 5 : right - 4].mean(axis=(0, 1))[2] < 80  # yellow
    pixels = (255 - np.frombuffer(Image.FromString(data).data, dtype=np.uint8)).tobytes()
    reordered = (
        Image(data=b"\0" * 12).SerializeToString()  # a first data, replaced by the last
        + Image(data=pixels).SerializeToString()
        + Image(
            sensor="front", time_s=1.0, width=800, height=600, encoding="rgb8"
        ).SerializeToString()
    )
    assert view.update({"camera": reordered})
    later = view.shown()
    assert later is not None and (later.number, later.time_s, later.sensor) == (2, 1.0, "front")
    assert bytes(later.pixels) == pixels
    inverted = np.asarray(PillowImage.open(io.BytesIO(view.jpeg(2) or b"")))
    assert inverted[top + 2 : bottom - 1, left + 5 : right - 4].mean(axis=(0, 1))[2] > 180  # blue
    assert view.jpeg(1) is not None  # frame 1, still kept, pictured on its own


async def test_a_bad_camera_input_is_ignored_and_the_run_goes_on(
    service: MapService, run: Run
) -> None:
    depth = Image(sensor="lidar", encoding="depth16-class-id", width=2, height=1, data=b"\0" * 12)
    await run.start()
    await run.steps(
        2, inputs=lambda v: {**v, "camera": depth.SerializeToString(), "detections": b"\xff"}
    )
    assert service.state.camera.to_json() is None
    assert service.state.steps == 2


@pytest.mark.skipif(not CHROMIUM.exists(), reason=NO_CHROMIUM)
async def test_the_page_shows_the_frame_with_its_boxes_in_chromium(
    service: MapService, run: Run, browser: Any
) -> None:
    page = await browser.new_page(viewport={"width": 1280, "height": 900})
    errors = page_errors(page)
    await page.goto(service.url)
    await page.wait_for_function("window.coupler && window.coupler.ready")
    assert await page.locator("#camera-panel").is_hidden()  # no camera connected yet
    await run.start()
    await run.steps(9, pace_s=0.05, inputs=with_camera(run))  # passes balises 101 and 102
    await page.wait_for_function(
        "window.coupler.camera && window.coupler.camera.judged && "
        "window.coupler.frameLoaded === window.coupler.camera.frame"
    )
    assert await page.locator("#camera-panel").is_visible()
    assert await page.locator("#camera-boxes rect.detection").count() == 1
    natural = await page.evaluate("document.getElementById('camera-frame').naturalWidth")
    assert natural == 800
    caption = await page.locator("#camera-caption").text_content()
    assert caption == "front at 7.0 s, 1 balise(s) detected"
    # the panel sits above the balise table in the side bar
    panel = await page.locator("#camera-panel").bounding_box()
    table = await page.locator("#readings-panel").bounding_box()
    assert panel is not None and table is not None and panel["y"] < table["y"]
    await page.wait_for_function("window.coupler.readingIds().length >= 2")
    assert errors == []
    ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
    picture = await page.screenshot(path=str(ARTIFACT))
    assert len(picture) > 10_000
