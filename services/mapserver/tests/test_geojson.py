"""The GeoJSON endpoint and the static page over a real aiohttp server."""

from __future__ import annotations

from pathlib import Path

import aiohttp
import pytest

from mapserver import assets

from .support import EXPECTED_IDS, MapService


async def test_geojson_has_the_line_the_balises_and_the_stations(service: MapService) -> None:
    async with (
        aiohttp.ClientSession() as session,
        session.get(service.url + "api/geojson") as response,
    ):
        assert response.status == 200
        assert response.content_type == "application/geo+json"
        collection = await response.json(content_type=None)
    assert collection["type"] == "FeatureCollection"
    kinds = [f["properties"]["kind"] for f in collection["features"]]
    assert kinds.count("track") == 1
    track = collection["features"][0]
    assert track["geometry"]["type"] == "LineString"
    lon, lat = track["geometry"]["coordinates"][0]  # RFC 7946 order
    assert (round(lat, 6), round(lon, 6)) == (50.0, 12.0)
    balises = [
        f["properties"] for f in collection["features"] if f["properties"]["kind"] == "balise"
    ]
    assert [b["id"] for b in balises] == EXPECTED_IDS
    assert [b["group"] for b in balises] == [10, 10, 20, 30, 30, 30, 40]
    stations = [
        f["properties"]["name"]
        for f in collection["features"]
        if f["properties"]["kind"] == "station"
    ]
    assert stations == ["West", "North"]


async def test_page_and_vendored_leaflet_are_served_locally(service: MapService) -> None:
    async with aiohttp.ClientSession() as session:
        for path in ("", "static/app.js", "static/vendor/leaflet/leaflet.js", "api/config"):
            async with session.get(service.url + path) as response:
                assert response.status == 200, path
        async with session.get(service.url + "api/config") as response:
            assert await response.json() == {"tile_url": "", "tile_attribution": ""}


async def test_missing_leaflet_gives_the_fix(
    service: MapService, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(assets, "VENDOR", tmp_path / "vendor" / "leaflet")
    async with aiohttp.ClientSession() as session, session.get(service.url) as response:
        assert response.status == 503
        assert "make setup" in await response.text()
