"""Debian's Chromium, driven by Playwright, for the tests of the project's web pages (the
monitor, the map, ``coupler plot``'s page): its path and flags in one place.

    @pytest.mark.skipif(not CHROMIUM.exists(), reason=NO_CHROMIUM)
    async def test_the_page(...):
        async with chromium() as browser:
            page = await browser.new_page()

Playwright (the workspace's dev dependency) is imported when a browser is started.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

__all__ = ["ARGUMENTS", "CHROMIUM", "NO_CHROMIUM", "chromium"]

CHROMIUM = Path("/usr/bin/chromium")
"""Debian's Chromium (``.ci/run`` installs it); browser tests skip without it."""
NO_CHROMIUM = "Debian's chromium is not installed"
ARGUMENTS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
)
"""Headless, and nothing that reaches beyond the machine (updates, sync, QUIC)."""


@contextlib.asynccontextmanager
async def chromium() -> AsyncIterator[Any]:
    """A Playwright ``Browser`` of Debian's Chromium, closed (with Playwright) on the way out."""
    from playwright.async_api import async_playwright

    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(
            executable_path=str(CHROMIUM), args=list(ARGUMENTS)
        )
        try:
            yield browser
        finally:
            await browser.close()
