"""The page in real headless Chromium (Debian's) during a driven run over the test line.

Run (RemoteParticipant) --gRPC--> map server --SSE--> Chromium (Playwright) --> screenshot
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from coupler_dev.browser import CHROMIUM

from .support import EXPECTED_IDS, REPO, MapService, Run, page_errors

ARTIFACT = REPO / "test-artifacts" / "mapserver.png"

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason="Debian's chromium is not installed (apt-get install -y chromium); browser test skipped",
)


@pytest.mark.slow
async def test_train_moves_and_readings_appear_in_chromium(
    service: MapService, run: Run, browser: Any
) -> None:
    page = await browser.new_page(viewport={"width": 1280, "height": 760})
    errors = page_errors(page)
    outside: list[str] = []

    def only_local(request: Any) -> None:
        if not request.url.startswith(service.url):
            outside.append(request.url)

    page.on("request", only_local)
    await page.goto(service.url)
    await page.wait_for_function("window.coupler && window.coupler.ready")
    assert await page.locator("#map.no-tiles").count() == 1  # no tile server configured
    assert await page.locator("path.leaflet-interactive").count() >= 8  # line + balises

    await run.start()
    await run.steps(8, pace_s=0.05)  # 200 m: 101 and 102 passed
    await page.wait_for_selector("#train")
    await page.wait_for_function("window.coupler.readingIds().length >= 2")
    early = await page.evaluate("window.coupler.trainLatLng()")
    early_box = await page.locator("#train").bounding_box()

    await run.to_end(pace_s=0.02)
    await run.participant.terminate("stop time reached")
    await page.wait_for_function(f"window.coupler.readingIds().length >= {len(EXPECTED_IDS)}")
    await page.wait_for_selector("#run-status.ended")
    late = await page.evaluate("window.coupler.trainLatLng()")
    late_box = await page.locator("#train").bounding_box()

    assert (early["lat"], early["lng"]) != (late["lat"], late["lng"])
    end = run.infrastructure.model.position(run.length)
    assert late["lat"] == pytest.approx(end.latitude_deg, abs=1e-7)
    assert late["lng"] == pytest.approx(end.longitude_deg, abs=1e-7)
    assert early_box is not None and late_box is not None
    moved = abs(late_box["x"] - early_box["x"]) + abs(late_box["y"] - early_box["y"])
    assert moved > 50, f"train marker moved only {moved:.1f} px on screen"

    ids = await page.eval_on_selector_all(
        "#readings tbody tr", "rows => rows.map(r => Number(r.dataset.baliseId))"
    )
    assert ids == EXPECTED_IDS
    assert await page.locator("#run-id").text_content() == "test-run"
    assert errors == []
    assert outside == [], "the page fetched something from outside the map server"

    ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
    await page.screenshot(path=str(ARTIFACT), full_page=True)
    print(f"screenshot: {ARTIFACT}")

    # a second browser joining now gets the whole run at once
    other = await browser.new_page()
    await other.goto(service.url)
    await other.wait_for_function(f"window.coupler.readingIds().length === {len(EXPECTED_IDS)}")
    assert await other.evaluate("window.coupler.readingIds()") == EXPECTED_IDS
    await asyncio.sleep(0)
