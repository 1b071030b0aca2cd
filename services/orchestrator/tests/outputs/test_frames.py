"""Camera frames in results: never text in results.csv; numbered PNG files when picked.

    Camera (frame: coupler.v1.Image, rgb8 8 x 4 and depth: depth16-class-id) --> Gain.blob

``coupler run`` as a process: by default results.csv has no frame column (TrainState-like
messages and plain bytes stay, as JSON and hex); ``--output-variables`` picking a frame column
writes ``frames/Camera.frame/<point>.png`` and puts that name in the cell. The monitor serves
each camera channel's latest frame (and its page shows it), keeping no history of frames.
"""

from __future__ import annotations

import asyncio
import io
import json
import zlib
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import aiohttp
import pytest
from PIL import Image as Pillow

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.participant import Values
from coupler.testing import remote
from coupler.v1.sensors_pb2 import Image
from coupler_dev.browser import CHROMIUM, NO_CHROMIUM, chromium
from coupler_orchestrator.observer import RunEnd
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.outputs.files import ResultsError
from coupler_orchestrator.outputs.kept_frames import PENDING, KeptFrames
from coupler_orchestrator.outputs.monitor import MonitorServer
from coupler_orchestrator.runner import run_scenario

from ..support import Coupler
from ..support.frames import SSD, Camera, Fleet

WIDTH, HEIGHT = 8, 4
RED = (
    "(() => { const img = document.querySelector("
    "\"#camera-list img[data-channel='Camera.frame']\");"
    " const canvas = document.createElement('canvas'); canvas.width = img.naturalWidth;"
    " canvas.height = img.naturalHeight; const context = canvas.getContext('2d');"
    " context.drawImage(img, 0, 0); return context.getImageData(5, 2, 1, 1).data[0]; })()"
)
"""The red of the monitor page's shown Camera.frame at (5, 2): the step it shows."""


@pytest.fixture
def ssd(tmp_path: Path) -> Path:
    camera = remote("Camera", "grpc://127.0.0.1:${CAMERA_PORT}", outputs=["frame", "depth"])
    return replace(SSD, components=[camera, *SSD.components[1:]]).write(tmp_path / "frames.ssd")


def frame(step: int) -> bytes:
    """An rgb8 frame whose pixel (c, r) is (step, c, r)."""
    data = bytes(v for r in range(HEIGHT) for c in range(WIDTH) for v in (step, c, r))
    image = Image(sensor="front", width=WIDTH, height=HEIGHT, encoding="rgb8", data=data)
    return image.SerializeToString()


class ImageCamera(Camera):
    """``frame``: an rgb8 Image per step; ``depth``: a depth16-class-id Image."""

    async def describe(self) -> Description:
        channels = tuple(
            Channel(
                name=name,
                causality=Causality.OUTPUT,
                type=ValueType.BINARY,
                message_type="coupler.v1.Image",
            )
            for name in ("frame", "depth")
        )
        return Description(name="Camera", channels=channels, implementation="tests.ImageCamera")

    async def initialize(self, setup: RunSetup) -> Values:
        self.steps = 0
        return {"frame": b"", "depth": b""}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self.steps += 1
        samples = [0x1234 + self.steps] * (WIDTH * HEIGHT * 3)
        depth = Image(
            width=WIDTH,
            height=HEIGHT,
            encoding="depth16-class-id",
            data=b"".join(s.to_bytes(2, "little") for s in samples),
        )
        return {"frame": frame(self.steps), "depth": depth.SerializeToString()}


def test_frames_are_left_out_of_results_csv(
    ssd: Path,
    tmp_path: Path,
    fleet: Fleet,
) -> None:
    fleet.serve(camera=ImageCamera(0))
    out = tmp_path / "out"
    outcome = Coupler.process("run", ssd, "--step", "0.1", "--out", out)
    assert outcome.code == 0, outcome.err
    rows = Coupler.results(out)
    assert not [name for name in rows[0] if name.startswith("Camera.")]
    # plain bytes stay, as hex: the frame reversed by Gain (a step later: Jacobi)
    assert rows[2]["Gain.blob_out"] == frame(1)[::-1].hex()
    assert not (out / "frames").exists()


def test_picked_frames_are_numbered_png_files(
    ssd: Path,
    tmp_path: Path,
    fleet: Fleet,
) -> None:
    fleet.serve(camera=ImageCamera(0))
    out = tmp_path / "out"
    outcome = Coupler.process(
        "run", ssd, "--step", "0.1", "--out", out, "--output-variables", "Camera.*"
    )
    assert outcome.code == 0, outcome.err
    rows = Coupler.results(out)
    assert [row["Camera.frame"] for row in rows] == [
        "",  # no frame at t_0
        "frames/Camera.frame/000001.png",
        "frames/Camera.frame/000002.png",
        "frames/Camera.frame/000003.png",
    ]
    for step in (1, 2, 3):
        with Pillow.open(out / f"frames/Camera.frame/{step:06d}.png") as png:
            assert (png.mode, png.size) == ("RGB", (WIDTH, HEIGHT))
            assert png.getpixel((5, 2)) == (step, 5, 2)
    depth = (out / rows[2]["Camera.depth"]).read_bytes()
    assert depth.startswith(b"\x89PNG") and b"IHDR" in depth
    start = depth.index(b"IDAT") + 4
    raw = zlib.decompressobj().decompress(depth[start:])
    assert raw[:7] == b"\0\x12\x36\x12\x36\x12\x36"  # filter byte, then big-endian samples


def test_only_the_picked_frames_are_written(
    ssd: Path,
    tmp_path: Path,
    fleet: Fleet,
) -> None:
    fleet.serve(camera=ImageCamera(0))
    out = tmp_path / "out"
    outcome = Coupler.process(
        "run", ssd, "--step", "0.1", "--out", out, "--output-variables", "Camera.depth"
    )
    assert outcome.code == 0, outcome.err
    assert list(Coupler.results(out)[0]) == ["time", "Camera.depth"]
    assert sorted(p.name for p in (out / "frames").iterdir()) == ["Camera.depth"]


# --- the monitor: the latest frame of each camera channel --------------------------------------


async def test_the_monitor_serves_the_latest_frame_and_keeps_no_frame_history(
    ssd: Path,
    tmp_path: Path,
    fleet: Fleet,
) -> None:
    fleet.serve(camera=ImageCamera(0))
    async with MonitorServer("127.0.0.1:0") as monitor:
        options = RunOptions(stop_time=0.3, step_size=0.1)
        outcome = await run_scenario(ssd, options, out_dir=tmp_path, observers=[monitor.state])
        async with aiohttp.ClientSession() as session:
            async with session.get(f"{monitor.url}api/frame/Camera.frame") as reply:
                assert reply.status == 200 and reply.content_type == "image/png"
                with Pillow.open(io.BytesIO(await reply.read())) as png:
                    assert png.size == (WIDTH, HEIGHT) and png.getpixel((5, 2)) == (3, 5, 2)
            async with session.get(f"{monitor.url}api/frame/Gain.y") as reply:
                assert reply.status == 404
                assert await reply.text() == (
                    "'Gain.y' is not a camera channel of this run (Camera.frame, Camera.depth)"
                )
            async with session.get(f"{monitor.url}api/state") as reply:
                state = await reply.json()
    assert outcome.end.status == "completed"
    assert state["layout"]["frames"] == ["Camera.frame", "Camera.depth"]
    kept = monitor.state.values.rows
    assert len(kept) == 4 and not any(isinstance(v, bytes) for row in kept for v in row)


@pytest.mark.slow
@pytest.mark.skipif(not CHROMIUM.exists(), reason=NO_CHROMIUM)
async def test_the_monitor_page_shows_the_latest_frame(
    ssd: Path,
    tmp_path: Path,
    fleet: Fleet,
) -> None:
    fleet.serve(camera=ImageCamera(0))
    async with MonitorServer("127.0.0.1:0") as monitor:
        options = RunOptions(stop_time=4.0, step_size=0.1, realtime_factor=1.0)
        running = asyncio.create_task(
            run_scenario(ssd, options, out_dir=tmp_path, observers=[monitor.state])
        )
        async with chromium() as browser:
            page = await browser.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            await page.goto(monitor.url)
            shown = "document.querySelector(\"#camera-list img[data-channel='Camera.frame']\")"
            await page.wait_for_function(f"{shown} && {shown}.naturalWidth === {WIDTH}")
            hidden = await page.evaluate("document.getElementById('cameras').hidden")
            outcome = await running
            # the page follows the run to its last frame (step 40: red 40)
            await page.wait_for_function(f"{RED} === 40", arg=None)
    assert outcome.end.status == "completed"
    assert not hidden and errors == []


class _EveryFifth:
    """A keeper wanting every fifth point's frames, one before and one after."""

    frames = "Camera.frame"
    watches = ("Camera.point",)
    before = 1
    after = 1

    def wants(self, values: list[Value]) -> bool:
        return int(values[0]) % 5 == 0


def _kept_frames(folder: Path) -> KeptFrames:
    from collections import deque

    from coupler_orchestrator.outputs.kept_frames import _Kept

    observer = KeptFrames(folder)
    keeper = _EveryFifth()
    observer._kept.append(
        _Kept(keeper=keeper, frame=0, watched=[1], folder=folder / "kept-frames" / keeper.frames,
              ring=deque(maxlen=2))
    )  # fmt: skip
    return observer


def _frame(point: int) -> bytes:
    pixels = bytes([point % 256, 0, 0]) * (WIDTH * HEIGHT)
    return Image(encoding="rgb8", width=WIDTH, height=HEIGHT, data=pixels, time_s=point / 10)\
        .SerializeToString()  # fmt: skip


def test_kept_frames_are_written_off_the_step_loop_in_order(tmp_path: Path) -> None:
    """More points wanted than frames may wait for the writer thread: every frame around a
    wanted point is a PNG of its own pixels, and the index lists them in order."""
    observer = _kept_frames(tmp_path)
    for point in range(3 * PENDING * 5):
        observer.stepped(point / 10, [_frame(point), point])
    observer.closing(RunEnd(status="completed", reason="", steps=0, end_time=0.0, wall_time=0.0))
    folder = tmp_path / "kept-frames" / "Camera.frame"
    index = json.loads((folder / "index.json").read_text())["frames"]
    points = [e["point"] for e in index]
    assert points == sorted({p + d for p in range(0, 3 * PENDING * 5, 5) for d in (-1, 0, 1)}
                            - {-1, 3 * PENDING * 5})  # fmt: skip
    for entry in index:
        with Pillow.open(folder / entry["file"]) as png:
            assert png.getpixel((0, 0)) == (entry["point"] % 256, 0, 0)


def test_a_kept_frame_that_cannot_be_written_fails_the_run(tmp_path: Path) -> None:
    (tmp_path / "kept-frames").write_text("a file where the folder goes")
    observer = _kept_frames(tmp_path)
    with pytest.raises(ResultsError, match=r"cannot write .*kept-frames"):
        for point in range(10):
            observer.stepped(point / 10, [_frame(point), point])
        observer.closing(
            RunEnd(status="completed", reason="", steps=0, end_time=0.0, wall_time=0.0)
        )
