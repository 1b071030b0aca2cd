"""What the bridge's tests share besides fixtures (those are in conftest.py): a tiny OpenRails,
its replies and a server for it.
"""

from __future__ import annotations

import asyncio
import copy
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import Any

from aiohttp import web

from coupler.client import RemoteParticipant

RANGES = [  # GET /API/CABCONTROLS of a tiny OpenRails
    {"TypeName": name, "MinValue": lo, "MaxValue": hi, "RangeFraction": 0.0}
    for name, lo, hi in [
        ("THROTTLE", 0.0, 1.0),
        ("TRAIN_BRAKE", 0.0, 1.0),
        ("DYNAMIC_BRAKE", 0.0, 1.0),
        ("DIRECTION", -1.0, 1.0),
    ]
]


TRACK = {  # the parts of a well-formed step reply
    "trackNodeIndex": 1,
    "trackNodeLength": 500.0,
    "trackNodeOffset": 42.0,
    "trackVectorSectionIndex": 0,
    "movementDirection": "Forward",
}
WORLD = {"tileX": 1, "tileZ": 2, "x": 3.0, "y": 4.0, "z": 5.0}
GOOD_TRAIN: dict[str, Any] = {
    "location": WORLD,
    "trackLocation": TRACK,
    "rearTrackLocation": TRACK,
    "rotation": 0.5,
    "locomotiveState": {
        "v": 1.5,
        "a": 0.1,
        "distance": 12.0,
        "wheelslip": False,
        "wheelskid": False,
    },
    "trainLength": {"length": 41.7},
    "carPositions": {"Front": WORLD, "Rear": WORLD},
}
Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


def step_reply(**train_changes: Any) -> dict[str, Any]:
    """A step reply; ``locomotiveState__v="x"`` changes a field, ``=KeyError`` removes it."""
    train = copy.deepcopy(GOOD_TRAIN)
    for dotted, value in train_changes.items():
        *parents, leaf = dotted.split("__")
        node = train
        for part in parents:
            node = node[part]
        if value is KeyError:
            del node[leaf]
        else:
            node[leaf] = value
    return {"trains": {"PLAYER": train}, "CameraSensors": {}}


def tiny_openrails(*, step: Handler | None = None, controls: Any = RANGES) -> web.Application:
    """An OpenRails for what the mock cannot do: READY, the GETs the bridge reads (``controls``
    as the control list), POST /API/CABCONTROLS by ``step`` (default: a good reply); no
    RESET (404, as OpenRails)."""

    async def ready(request: web.Request) -> web.Response:
        return web.Response(status=200)

    async def cabcontrols(request: web.Request) -> web.Response:
        return web.json_response(controls)

    async def map_(request: web.Request) -> web.Response:
        return web.json_response({"LatLon": {"Lat": 50.5, "Lon": 13.0}, "DirectionDeg": 90.0})

    async def display(request: web.Request) -> web.Response:
        return web.json_response([{"FirstCol": "Speed", "LastCol": "0.0 km/h"}])

    async def good_step(request: web.Request) -> web.Response:
        return web.json_response(step_reply())

    app = web.Application()
    app.router.add_get("/API/READY", ready)
    app.router.add_get("/API/CABCONTROLS", cabcontrols)
    app.router.add_post("/API/CABCONTROLS", step or good_step)
    app.router.add_get("/API/MAP", map_)
    app.router.add_get("/API/TRAINDRIVINGDISPLAY", display)
    return app


Mock = Callable[..., AbstractAsyncContextManager[str]]
Bridge = Callable[..., AbstractAsyncContextManager[RemoteParticipant]]


@asynccontextmanager
async def serve_app(app: web.Application, port: int = 0) -> AsyncIterator[str]:
    """``app`` on 127.0.0.1, ``port`` (0: a free one); yields its base URL."""
    runner = web.AppRunner(app, shutdown_timeout=0.5)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", port)
    await site.start()
    port = runner.addresses[0][1]
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        await runner.cleanup()


MIB = 1024 * 1024
HUGE = 400 * MIB


class Firehose:
    """A 400 MB answer, generated as it is sent; counts what got out before the bridge hung up."""

    def __init__(self, *, declare_length: bool) -> None:
        self.declare_length = declare_length
        self.sent = 0
        self.finished = asyncio.Event()

    async def handle(self, request: web.Request) -> web.StreamResponse:
        response = web.StreamResponse(headers={"Content-Type": "application/json"})
        if self.declare_length:
            response.content_length = HUGE
        await response.prepare(request)
        chunk = b'{"trains": {"PLAYER": {"padding": "' + b"x" * (MIB - 36)
        try:
            while self.sent < HUGE:
                await response.write(chunk)
                self.sent += len(chunk)
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            self.finished.set()
        return response
