"""The railway scenario's perception variant end to end: `coupler fleet` with the variant's
services as real local processes, the map in Chromium, the detections scored.

    Driver (FMU) == throttle, brake ==> OpenRails bridge ==HTTP==> OpenRails mock (camera)
    OpenRails bridge == front (800 x 600 Image), train_state ==> Perception == detections ==> Map
    OpenRails bridge == distance ==> TrackBalises == passed_in_step ==> Map
    OpenRails bridge == front ==> Map

The fleet file is the scenario's own (scenarios/railway/perception-fleet.toml: its services,
commands and health checks), run for the first 40 s only and paced at real time, so the map
can be watched while the train passes the first two balise groups (120 m and 320 m). The run
scores itself against TrackBalises (summary.json `reports.perception`, perception-report.json),
as `python -m coupler_railway.scoring` does: every balise passed was seen before it was passed,
within a metre, and nothing else was seen.
"""

from __future__ import annotations

import asyncio
import base64
import csv
import io
import json
import os
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path
from typing import Any

import aiohttp
import numpy as np
import pytest
from PIL import Image

from coupler.testing import free_ports
from coupler_dev.browser import CHROMIUM, chromium

ROOT = Path(__file__).resolve().parents[2]
FLEET = ROOT / "scenarios" / "railway" / "perception-fleet.toml"
FMUS = ROOT / "build" / "fmus"
COUPLER = Path(sys.executable).parent / "coupler"
STOP_TIME = "40"
ARTIFACT = ROOT / "test-artifacts" / "railway-perception-map.png"
PORTS = ("MOCK_PORT", "BRIDGE_PORT", "BALISE_PORT", "PERCEPTION_PORT", "MAP_PORT",
         "MAP_HTTP_PORT", "MONITOR_PORT")  # fmt: skip

pytestmark = pytest.mark.timeout(600)


SHOWN = """() => {
  const c = window.coupler;
  if (!(c && c.camera && c.camera.judged && c.frameLoaded === c.camera.frame &&
        c.camera.detections.some((d) => d.distance_ahead_m < 25))) return null;
  const img = document.getElementById('camera-frame');
  const canvas = document.createElement('canvas');
  canvas.width = img.naturalWidth;
  canvas.height = img.naturalHeight;
  canvas.getContext('2d').drawImage(img, 0, 0);
  return {camera: c.camera, width: img.naturalWidth, png: canvas.toDataURL('image/png'),
          boxes: document.querySelectorAll('#camera-boxes rect.detection').length};
}"""
"""The map once it shows a frame with a balise detected within 25 m, at one instant: camera
state, frame width, its pixels (PNG), boxes; null until then."""


def short_fleet(folder: Path, out: Path) -> Path:
    """The scenario's fleet file, its run stopped at STOP_TIME and written to ``out``; the
    services, commands and health checks as they are."""
    text = FLEET.read_text()
    services = text[text.index("[[service]]") :]
    args = ["--stop-time", STOP_TIME]  # every channel recorded: frames are left out by default
    path = folder / "fleet.toml"
    path.write_text(
        f'[scenario]\nssp = "scenarios/railway/Perception.ssd"\nout = "{out}"\n'
        f"args = {json.dumps(args)}\n\n{services}"
    )
    return path


def times_in(value: Any) -> list[float]:
    """Every time in a decoded JSON value: the numbers of keys named ``time_s`` or ``..._at_s``."""
    if isinstance(value, dict):
        found = [v for k, v in value.items() if k == "time_s" or k.endswith("_at_s")]
        return [float(v) for v in found if isinstance(v, int | float)] + [
            t for v in value.values() for t in times_in(v)
        ]
    if isinstance(value, list):
        return [t for v in value for t in times_in(v)]
    return []


def off_the_grid(times: list[float], start: float, step: float) -> list[float]:
    """The times that are not the run's grid point ``start + k * step`` as the user wrote it
    (the double nearest the exact decimal: 9.2, never 9.200000000000001)."""
    t0, h = Fraction(repr(start)), Fraction(repr(step))
    return [t for t in times if t != float(t0 + round((Fraction(t) - t0) / h) * h)]


async def wait_for_map(url: str, process: subprocess.Popen[str], within: float = 180.0) -> None:
    deadline = time.monotonic() + within
    async with aiohttp.ClientSession() as session:
        while time.monotonic() < deadline:
            assert process.poll() is None, "the fleet ended before the map served"
            try:
                async with session.get(url + "healthz") as response:
                    if response.status == 200:
                        return
            except aiohttp.ClientError:
                pass
            await asyncio.sleep(0.5)
    raise AssertionError(f"the map at {url} did not answer within {within:.0f} s")


async def watch(url: str) -> dict[str, Any]:
    """The map in Chromium until it shows a frame with a balise detected within 25 m: the
    screenshot, and the frame (JPEG from the map) with its boxes."""
    async with chromium() as browser:
        page = await browser.new_page(viewport={"width": 1280, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        await page.goto(url)
        # one evaluation: the camera state, its boxes and the very picture shown with them
        # (the map keeps only its last few frames: fetched later, another one may come)
        shown_now = await page.wait_for_function(SHOWN, timeout=240_000)
        seen = await shown_now.json_value()
        ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
        await page.screenshot(path=str(ARTIFACT))
        assert errors == []
    camera, shown, boxes = seen["camera"], seen["width"], seen["boxes"]
    png = base64.b64decode(seen["png"].split(",", 1)[1])
    picture = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    return {"camera": camera, "natural_width": shown, "boxes": boxes, "picture": picture}


async def observe(url: str, process: subprocess.Popen[str], browser: bool) -> Any:
    """Wait for the map, then watch it in Chromium (when there is one)."""
    await wait_for_map(url, process)
    return await watch(url) if browser else None


@pytest.mark.slow
def test_the_perception_variant_end_to_end(tmp_path: Path) -> None:
    for fmu in ("Driver2.fmu", "TrackBalises.fmu"):
        if not (FMUS / fmu).exists():
            pytest.fail(f"{FMUS / fmu} is missing: run 'make setup' (make test does)")
    out = tmp_path / "run"
    ports = {name: str(port) for name, port in zip(PORTS, free_ports(len(PORTS)), strict=True)}
    env = {**os.environ, **ports}
    map_url = f"http://127.0.0.1:{ports['MAP_HTTP_PORT']}/"
    command = [str(COUPLER), "fleet", str(short_fleet(tmp_path, out)), "--exit",
               "--realtime-factor", "1"]  # fmt: skip
    with subprocess.Popen(
        command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    ) as process:
        try:
            seen = asyncio.run(observe(map_url, process, CHROMIUM.exists()))
            output, _ = process.communicate(timeout=400)
        finally:
            if process.poll() is None:
                process.terminate()
    assert process.returncode == 0, output[-3000:]
    out = out / "latest"  # a fleet file's `out` is a base: each run has a folder of its own

    # the run, and the frames kept out of results.csv
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    with (out / "results.csv").open() as handle:
        header = next(csv.reader(handle))
    assert "Perception.detections" in header and "OpenRails.front" not in header

    # the map showed a real frame: the track's rails, and a yellow balise in each box
    if seen is not None:
        camera, picture = seen["camera"], seen["picture"]
        assert seen["natural_width"] == 800 and seen["boxes"] == len(camera["detections"])
        assert picture.shape == (600, 800, 3)
        rails = picture[560:600, 250:550].reshape(-1, 3).astype(int)
        assert ((rails.min(axis=1) > 150) & (np.ptp(rails, axis=1) < 30)).any()  # grey steel
        for box in camera["detections"]:
            block = picture[box["top"] : box["bottom"] + 1, box["left"] : box["right"] + 1]
            r, g, b = (block[..., i].astype(int) for i in range(3))
            assert ((r > 150) & (g > 110) & (b < 100)).any(), box  # yellow, after JPEG
            assert 5.0 < box["distance_ahead_m"] <= 40.0

    # the run scored itself (coupler-railway's `coupler.reports` entry point): both groups seen
    # before they were passed; the scoring command gives the same report
    scored_by_run = summary["reports"]["perception"]
    assert scored_by_run["recall"] == 1.0 and scored_by_run["missed"] == []
    assert json.loads((out / "perception-report.json").read_text())["recall"] == 1.0
    scored = subprocess.run(
        [sys.executable, "-m", "coupler_railway.scoring", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert scored.returncode == 0, scored.stderr
    report = json.loads((out / "perception-report.json").read_text())
    passed = [b["balise_id"] for b in report["balises"]]
    assert passed == [1000, 1001, 1010, 1011, 1012]
    assert report["recall"] == 1.0 and report["precision"] == 1.0
    assert {k: report[k] for k in scored_by_run if k in report} == {
        k: v for k, v in scored_by_run.items() if k in report
    }
    assert report["max_abs_error_m"] < 1.0
    for balise in report["balises"]:
        assert balise["first_detected_at_s"] < balise["passed_at_s"]

    # every time a participant or the report says is on the run's grid, as written (issue 45
    # item 4): the train states and detections (the camera frames' times) in results.csv, the
    # report's JSON and its CSV tables
    start, step = summary["start_time"], summary["step_size"]
    with (out / "results.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    said: list[float] = []
    for column in ("OpenRails.train_state", "Perception.detections"):
        said += times_in([json.loads(row[column]) for row in rows if row[column]])
    assert len(said) >= 2 * len(rows) > 100 and off_the_grid(said, start, step) == []
    said = times_in(report)
    assert len(said) >= 10 and off_the_grid(said, start, step) == []
    for table in out.glob("perception-*.csv"):
        with table.open() as handle:
            cells = [
                text
                for row in csv.DictReader(handle)
                for name, text in row.items()
                if text and (name == "time_s" or name.endswith("_at_s"))
            ]
        shown = [float(text) for text in cells]
        assert off_the_grid(shown, start, step) == [], table.name
        assert cells == [repr(t) for t in shown], table.name  # 9.2 as 9.2
