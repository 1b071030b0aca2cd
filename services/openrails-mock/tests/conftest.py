"""A real mock on a free port, and a client session bound to it."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import aiohttp
import pytest
from aiohttp import web

from openrails_mock.api import create_app
from openrails_mock.config import MockConfig
from openrails_mock.route import Route

from .support import Serve


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
