"""Fan-out of the run's events to browsers, never making the run wait for one.

Each browser has a ``Subscriber``: a bounded queue filled by ``Feed.publish`` (called inside
DoStep, so it only appends and never awaits) and drained by that browser's connection.

- ``step`` events (train, status) are coalesced: only the latest waits to be sent.
- ``reading`` and ``run`` events queue up in order, at most ``backlog`` of them. A browser
  further behind loses its queue and gets a full snapshot instead, so it never misses a
  reading, and its memory stays bounded however slow it is.
- The first thing every browser gets is a snapshot: a late joiner sees the whole run so far.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable

from mapserver.state import Event, RunState


class Subscriber:
    """One browser's queue: a snapshot first, then events in order, steps coalesced."""

    def __init__(self, snapshot: Callable[[], Event], backlog: int) -> None:
        self._snapshot = snapshot
        self.backlog = backlog
        self._queue: deque[Event] = deque()
        self._latest: Event | None = None
        self._resync = True
        self._wake = asyncio.Event()
        self._wake.set()
        self.closed = False
        self.peak = 0
        """Most events ever queued at once (at most ``backlog`` plus the latest step)."""
        self.coalesced = 0
        """Step events replaced by a newer one before being sent."""
        self.resyncs = 0
        """Times the queue overflowed and a snapshot replaced it."""

    @property
    def pending(self) -> int:
        """Events waiting to be sent."""
        return len(self._queue) + (self._latest is not None)

    def offer(self, event: Event) -> None:
        """Queue ``event``; never blocks, never grows beyond the backlog."""
        if self.closed or self._resync:
            self._wake.set()
            return  # the snapshot about to be sent will contain it
        if event.droppable:
            if self._latest is not None:
                self.coalesced += 1
            self._latest = event
        elif len(self._queue) >= self.backlog:
            self._queue.clear()
            self._latest = None
            self._resync = True
            self.resyncs += 1
        else:
            self._queue.append(event)
        self.peak = max(self.peak, self.pending)
        self._wake.set()

    def close(self) -> None:
        """Ends ``next()``: the server is shutting down."""
        self.closed = True
        self._wake.set()

    async def next(self, idle_s: float) -> list[Event] | None:
        """What to send now, [] after ``idle_s`` without news, None once closed."""
        if not self._wake.is_set():
            try:
                await asyncio.wait_for(self._wake.wait(), idle_s)
            except TimeoutError:
                return []
        self._wake.clear()
        if self.closed:
            return None
        if self._resync:
            self._resync = False
            self._queue.clear()
            self._latest = None
            return [self._snapshot()]  # taken now: every later event has a higher seq
        batch = list(self._queue)
        self._queue.clear()
        if self._latest is not None:
            batch.append(self._latest)
            batch.sort(key=lambda event: event.seq)  # in the order things happened
            self._latest = None
        return batch


class Feed:
    """Every connected browser's subscriber, fed from one ``RunState``."""

    def __init__(self, state: RunState, *, backlog: int = 256) -> None:
        self.state = state
        self.backlog = backlog
        self.subscribers: set[Subscriber] = set()
        state.listeners.append(self.publish)

    def publish(self, event: Event) -> None:
        for subscriber in self.subscribers:
            subscriber.offer(event)

    def subscribe(self) -> Subscriber:
        subscriber = Subscriber(self.state.snapshot, self.backlog)
        self.subscribers.add(subscriber)
        return subscriber

    def unsubscribe(self, subscriber: Subscriber) -> None:
        self.subscribers.discard(subscriber)

    def close(self) -> None:
        """Ends every stream (server shutdown)."""
        for subscriber in self.subscribers:
            subscriber.close()
