"""The web app: one page, its static files, and the run pushed over Server-Sent Events.

    GET /              the map page (503 with the fix when Leaflet is not installed)
    GET /static/...    app.js, style.css, vendor/leaflet/ (copied from npm at setup)
    GET /api/config    tile URL and attribution for the page
    GET /api/geojson   the line, balises and stations (coupler_railway.to_geojson)
    GET /api/state     the whole state so far (the snapshot event, as JSON)
    GET /api/events    text/event-stream: a snapshot, then events as DoSteps arrive
    GET /api/frame.jpg the camera frame shown (``?n=<frame number>``: that one, if still kept)
    GET /healthz       200 "ok"

Every event is one SSE message whose ``id`` is its sequence number and whose data is JSON with
a ``type``: ``snapshot`` (run, train, readings), ``step`` (run, train; latest wins),
``reading`` (one new row, with its 0-based ``index``) or ``run`` (started with ``reset``, or
ended). A browser that sees a gap in reading indexes reconnects and gets a fresh snapshot.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import structlog
from aiohttp import web

from coupler_railway import Infrastructure, to_geojson
from mapserver import assets
from mapserver.config import MapServerSettings
from mapserver.feed import Feed

log = structlog.get_logger("mapserver.web")

FEED = web.AppKey("feed", Feed)
SETTINGS = web.AppKey("settings", MapServerSettings)
GEOJSON = web.AppKey("geojson", bytes)
STATIC = assets.STATIC
SSE_HEADERS = {
    "Content-Type": "text/event-stream",
    "Cache-Control": "no-cache",
    "X-Accel-Buffering": "no",  # proxies must not buffer the stream
}

_MISSING_PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>Coupler map: set-up incomplete</title></head>
<body style="font-family: sans-serif; margin: 2em">
<h1>Coupler map server: Leaflet is not installed</h1>
<p>The page needs Leaflet in <code>{vendor}</code>; missing: {missing}.</p>
<p>Fix: {hint}, then reload.</p>
</body></html>
"""


def create_app(
    feed: Feed, infrastructure: Infrastructure, settings: MapServerSettings
) -> web.Application:
    """The web app over ``feed``; the GeoJSON is computed once here."""
    app = web.Application()
    app[FEED] = feed
    app[SETTINGS] = settings
    app[GEOJSON] = json.dumps(to_geojson(infrastructure)).encode()
    app.router.add_get("/", index)
    app.router.add_get("/api/config", config)
    app.router.add_get("/api/geojson", geojson)
    app.router.add_get("/api/state", state)
    app.router.add_get("/api/events", events)
    app.router.add_get("/api/frame.jpg", frame)
    app.router.add_get("/healthz", healthz)
    app.router.add_static("/static/", STATIC, append_version=False)
    app.on_shutdown.append(_close_streams)
    missing = assets.missing()
    if missing:
        log.error(
            "leaflet_missing",
            vendor=str(assets.VENDOR),
            missing=missing,
            fix=assets.SETUP_HINT,
        )
    return app


async def _close_streams(app: web.Application) -> None:
    app[FEED].close()


async def index(request: web.Request) -> web.StreamResponse:
    missing = assets.missing()
    if missing:
        log.error("leaflet_missing", missing=missing, fix=assets.SETUP_HINT)
        page = _MISSING_PAGE.format(
            vendor=assets.VENDOR, missing=", ".join(missing), hint=assets.SETUP_HINT
        )
        return web.Response(status=503, text=page, content_type="text/html")
    return web.FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})


async def config(request: web.Request) -> web.Response:
    settings = request.app[SETTINGS]
    return web.json_response(
        {"tile_url": settings.tile_url, "tile_attribution": settings.tile_attribution}
    )


async def geojson(request: web.Request) -> web.Response:
    return web.Response(body=request.app[GEOJSON], content_type="application/geo+json")


async def state(request: web.Request) -> web.Response:
    snapshot = request.app[FEED].state.snapshot()
    return web.Response(text=snapshot.json, content_type="application/json")


async def frame(request: web.Request) -> web.Response:
    """The camera frame as JPEG; 404 while no camera frame has arrived."""
    raw = request.query.get("n", "")
    number = int(raw) if raw.isdigit() else None
    picture = request.app[FEED].state.camera.jpeg(number)
    if picture is None:
        return web.json_response({"error": "no camera frame yet (connect Map.camera)"}, status=404)
    return web.Response(
        body=picture, content_type="image/jpeg", headers={"Cache-Control": "no-store"}
    )


async def healthz(request: web.Request) -> web.Response:
    return web.Response(text="ok")


async def events(request: web.Request) -> web.StreamResponse:
    """The push stream of one browser; ends when it leaves, stalls, or the server stops."""
    feed, settings = request.app[FEED], request.app[SETTINGS]
    response = web.StreamResponse(headers=SSE_HEADERS)
    try:
        await response.prepare(request)
    except ConnectionError:
        return response  # gone before the headers were out
    subscriber = feed.subscribe()
    peer = request.remote
    log.info("browser_connected", peer=peer, browsers=len(feed.subscribers))
    outcome = "left"
    try:
        await _send(response, b"retry: 1000\n\n", settings.client_write_timeout_s)
        while True:
            batch = await subscriber.next(settings.heartbeat_s)
            if batch is None:
                outcome = "server stopping"
                break
            body = "".join(f"id: {e.seq}\ndata: {e.json}\n\n" for e in batch) or ": idle\n\n"
            await _send(response, body.encode(), settings.client_write_timeout_s)
    except TimeoutError:
        outcome = f"stalled over {settings.client_write_timeout_s:g} s"
    except ConnectionError:
        outcome = "left"
    finally:
        feed.unsubscribe(subscriber)
        log.info(
            "browser_disconnected",
            peer=peer,
            outcome=outcome,
            resyncs=subscriber.resyncs,
            coalesced=subscriber.coalesced,
        )
    return response


async def _send(response: web.StreamResponse, data: bytes, limit_s: float) -> None:
    # write() waits while the browser's socket is full; only this browser's task waits
    await asyncio.wait_for(response.write(data), limit_s)


async def start_site(app: web.Application, host: str, port: int) -> tuple[web.AppRunner, int]:
    """Serve ``app`` on host:port (0: any free port); returns the runner and the bound port."""
    runner = web.AppRunner(app, access_log=None, shutdown_timeout=2.0)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    await site.start()
    bound: Any = runner.addresses[0]
    return runner, int(bound[1])
