"""The map's optional basemap, scale bar and follow-the-train toggle in Debian's Chromium.

tile server (aiohttp, port 0) <--tiles-- Chromium --page, SSE--> map server <--gRPC-- Run
"""

from __future__ import annotations

import io
import re
from collections.abc import AsyncIterator
from typing import Any

import pytest
from aiohttp import web
from PIL import Image

from coupler_dev.browser import CHROMIUM, NO_CHROMIUM
from mapserver.config import MapServerSettings

from .support import REPO, TEST_LINE, MapService, Run, page_errors

ARTIFACT = REPO / "test-artifacts" / "mapserver-controls.png"

pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason=NO_CHROMIUM)


class TileServer:
    """Serves one plain 256 px PNG for every tile and counts the requests."""

    def __init__(self) -> None:
        buffer = io.BytesIO()
        Image.new("RGB", (256, 256), (170, 211, 223)).save(buffer, "PNG")
        self.tile = buffer.getvalue()
        self.requests: list[str] = []
        self.url = ""

    async def handle(self, request: web.Request) -> web.Response:
        self.requests.append(request.path)
        return web.Response(body=self.tile, content_type="image/png")


@pytest.fixture
async def tiles() -> AsyncIterator[TileServer]:
    server = TileServer()
    app = web.Application()
    app.router.add_get("/tiles/{z}/{x}/{y}.png", server.handle)
    runner = web.AppRunner(app)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    port = runner.addresses[0][1]
    server.url = f"http://127.0.0.1:{port}/tiles/{{z}}/{{x}}/{{y}}.png"
    try:
        yield server
    finally:
        await runner.cleanup()


@pytest.fixture
def settings(tiles: TileServer) -> MapServerSettings:
    return MapServerSettings(
        railml=TEST_LINE,
        grpc_port=0,
        http_port=0,
        heartbeat_s=1.0,
        tile_url=tiles.url,
        tile_attribution="Test tiles",
    )


@pytest.mark.slow
async def test_basemap_scale_bar_and_following(
    service: MapService, run: Run, tiles: TileServer, browser: Any
) -> None:
    page = await browser.new_page(viewport={"width": 1280, "height": 760})
    errors = page_errors(page)
    await page.goto(service.url)
    await page.wait_for_function("window.coupler && window.coupler.ready")

    # the basemap from the settings' tile URL
    await page.wait_for_selector("img.leaflet-tile-loaded")
    assert tiles.requests and all(p.startswith("/tiles/") for p in tiles.requests)
    assert await page.locator("#map.no-tiles").count() == 0
    assert "Test tiles" in (await page.locator(".leaflet-control-attribution").inner_text())

    # a metric scale bar
    scale = await page.locator(".leaflet-control-scale-line").inner_text()
    assert re.fullmatch(r"\d+ (m|km)", scale.strip()), scale

    # following: the train stays in the middle while it moves
    await run.start()
    await run.steps(2)
    await page.wait_for_selector("#train")
    assert not await page.evaluate("window.coupler.following()")
    await page.evaluate("window.coupler.map.setZoom(17, {animate: false})")
    await page.check("#follow")
    await run.steps(12, pace_s=0.02)
    await page.wait_for_function("window.coupler.train.distance_m >= 14 * 25")
    on_screen = await page.evaluate("window.coupler.trainOnScreen()")
    assert abs(on_screen["x"] - on_screen["width"] / 2) < 3, on_screen
    assert abs(on_screen["y"] - on_screen["height"] / 2) < 3, on_screen
    ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
    await page.screenshot(path=str(ARTIFACT))

    # dragging the map ends following; the train then moves away from the middle
    box = await page.locator("#map").bounding_box()
    assert box is not None
    await page.mouse.move(box["x"] + 200, box["y"] + 200)
    await page.mouse.down()
    await page.mouse.move(box["x"] + 260, box["y"] + 240, steps=5)
    await page.mouse.up()
    assert not await page.evaluate("window.coupler.following()")
    await run.steps(12, pace_s=0.02)
    await page.wait_for_function("window.coupler.train.distance_m >= 26 * 25")
    moved = await page.evaluate("window.coupler.trainOnScreen()")
    assert abs(moved["x"] - moved["width"] / 2) + abs(moved["y"] - moved["height"] / 2) > 50
    assert errors == []
