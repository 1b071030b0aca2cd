"""``python -m mapserver`` as a user starts it: what it prints is where it serves."""

from __future__ import annotations

import asyncio
import re
import sys

import aiohttp
import pytest


@pytest.mark.slow
async def test_on_ipv6_it_prints_addresses_with_brackets() -> None:
    """``--grpc-host ::1 --http-host ::1``: the printed map URL is one a browser opens (it was
    http://::1:PORT/) and the participant's address one gRPC reads (grpc://[::1]:PORT)."""
    process = await asyncio.create_subprocess_exec(
        *(sys.executable, "-m", "mapserver", "--grpc-host", "::1", "--grpc-port", "0"),
        *("--http-host", "::1", "--http-port", "0", "--log-level", "WARNING"),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.DEVNULL,
    )
    try:
        assert process.stdout is not None
        line = (await asyncio.wait_for(process.stdout.readline(), 60)).decode()
        found = re.fullmatch(
            r"mapserver: participant at grpc://\[::1\]:(\d+), map at (http://\[::1\]:\d+/)\n", line
        )
        assert found, line
        async with aiohttp.ClientSession() as session, session.get(found.group(2)) as resp:
            assert resp.status == 200
    finally:
        process.terminate()
        await process.wait()
