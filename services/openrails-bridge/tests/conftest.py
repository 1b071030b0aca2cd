"""Real servers on port 0: the OpenRails mock (or a tiny faulty OpenRails), and the bridge
served by a real ParticipantServer, driven through a RemoteParticipant.

    RemoteParticipant --gRPC--> ParticipantServer(bridge) --HTTP--> openrails_mock / tiny
"""

from __future__ import annotations

import copy
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import Any

import pytest
from aiohttp import web

from coupler.client import RemoteParticipant
from coupler.testing import free_port, served
from openrails_bridge.__main__ import build
from openrails_bridge.config import BridgeSettings
from openrails_mock.api import create_app
from openrails_mock.config import MockConfig

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


@pytest.fixture
def mock() -> Mock:
    """The real OpenRails mock: ``async with mock(mode=..., loading_delay_s=...) as url``."""

    def _mock(port: int = 0, **config: Any) -> AbstractAsyncContextManager[str]:
        config.setdefault("loading_delay_s", 0.0)
        return serve_app(create_app(MockConfig(port=0, **config)), port)

    return _mock


@pytest.fixture
def bridge() -> Bridge:
    """The bridge on a real ParticipantServer: ``async with bridge(url, mode=...) as remote``;
    keywords are ``BridgeSettings`` but ``connect_timeout`` (how long to wait for SERVING)."""

    @asynccontextmanager
    async def _bridge(
        url: str, *, connect_timeout: float = 10.0, **settings: Any
    ) -> AsyncIterator[RemoteParticipant]:
        settings.setdefault("request_timeout_s", 2.0)
        settings.setdefault("ready_timeout_s", 5.0)
        participant = build(BridgeSettings(openrails_url=url, **settings))
        async with (
            served(participant) as server,
            RemoteParticipant(
                server.address, name="OpenRails", connect_timeout=connect_timeout
            ) as remote,
        ):
            yield remote

    return _bridge


@pytest.fixture
def closed_port() -> int:
    """A port nothing listens on."""
    return free_port()
