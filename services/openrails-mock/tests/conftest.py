"""A real mock on a free port, and a client session bound to it."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import Any

import aiohttp
import pytest
from aiohttp import web

from openrails_mock.api import create_app
from openrails_mock.config import MockConfig
from openrails_mock.route import Route

Serve = Callable[..., AbstractAsyncContextManager[aiohttp.ClientSession]]


def body(**controls: float) -> dict[str, Any]:
    """A lockstep POST /API/CABCONTROLS body setting ``controls`` of the PLAYER train."""
    return {
        "Controls": [
            {"LocomotiveName": "PLAYER", "TypeName": name, "ControlIndex": 1, "Value": value}
            for name, value in controls.items()
        ],
        "Commands": [],
        "SwitchCommands": {},
    }


class FakeClock:
    """Monotonic seconds that move only when the test says so."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def serve() -> Serve:
    @asynccontextmanager
    async def _serve(
        config: MockConfig,
        *,
        route: Route | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> AsyncIterator[aiohttp.ClientSession]:
        runner = web.AppRunner(create_app(config, route=route, clock=clock))
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        port = runner.addresses[0][1]
        try:
            async with aiohttp.ClientSession(base_url=f"http://127.0.0.1:{port}") as session:
                yield session
        finally:
            await runner.cleanup()

    return _serve
