"""An event loop in a thread of its own, for synchronous code that calls async Coupler code.

A mosaik simulator's methods are synchronous and called from mosaik's own event loop (in
process) or from ``mosaik_api_v3``'s (over TCP); the SDK's client (``RemoteParticipant``) is
async. Its calls run here, each waited for by the calling thread.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


class BackgroundLoop:
    """One event loop, running in a daemon thread until ``close``."""

    def __init__(self, name: str = "coupler-mosaik") -> None:
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name=name, daemon=True)
        self._thread.start()

    def run(self, coroutine: Coroutine[Any, Any, T]) -> T:
        """``coroutine``'s result (or its exception), run on the loop; blocks the caller."""
        return asyncio.run_coroutine_threadsafe(coroutine, self._loop).result()

    def close(self) -> None:
        """Stop the loop and join its thread (idempotent)."""
        if self._loop.is_closed():
            return
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=10)
        self._loop.close()
