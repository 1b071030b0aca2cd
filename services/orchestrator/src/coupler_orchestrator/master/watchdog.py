"""A thread that watches the calls the master makes on its own thread.

In-process FMUs step on the event loop's thread (no hop costs nothing). A step that never
returns would block that thread forever: no deadline, no Ctrl-C. The watchdog sees the step it
was told about outlive its deadline (or an interrupt arrive while the loop is blocked) and ends
the run from its own thread: the observers finish it (summary.json says why, results.csv keeps
every row) and, when the command line asked for it, the process exits — the only way to leave
a thread stuck in C code.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

Armed = tuple[str, float, float, float, str]
"""(what, simulated time, deadline [s], since [monotonic], cause) of the call under way."""

_active: Watchdog | None = None
IN_PROCESS = (
    "the FMU hangs in-process (the run had reached t={time:g} s; isolate it with "
    "--isolate-fmus to keep the orchestrator in charge)"
)
"""What a call past its deadline means, by default (``arm(cause=...)``)."""


def active() -> Watchdog | None:
    """The watchdog of the run going on in this process, if any."""
    return _active


class Watchdog:
    """Watches one run's synchronous calls; ``on_stuck(status, reason)`` ends the run."""

    def __init__(self, on_stuck: Callable[[str, str], None], *, poll: float = 0.2) -> None:
        self.on_stuck = on_stuck
        self.poll = poll
        self._armed: Armed | None = None
        """The call under way, as ``arm`` was told."""
        self._follow: Callable[[], Armed | None] | None = None
        """Says which call made in C is under way (``follow``)."""
        self._stop = threading.Event()
        self._fired = False
        self._thread = threading.Thread(target=self._watch, name="coupler-watchdog", daemon=True)

    def start(self) -> None:
        global _active
        _active = self
        self._thread.start()

    def stop(self) -> None:
        global _active
        if _active is self:
            _active = None
        self._stop.set()

    def arm(self, what: str, time_s: float, deadline: float, cause: str = IN_PROCESS) -> None:
        """A synchronous call (``what``, e.g. ``Plant.DoStep``) begins at simulated ``time_s``;
        ``cause`` says what it means when it outlives ``deadline`` ({time} is ``time_s``)."""
        self._armed = (what, time_s, deadline, time.monotonic(), cause)

    def disarm(self) -> None:
        self._armed = None

    def follow(self, under_way: Callable[[], Armed | None]) -> None:
        """Also watch calls made from C code, which cannot ``arm``: ``under_way()`` tells the
        one under way (read from this thread; None between calls)."""
        self._follow = under_way

    def _under_way(self) -> Armed | None:
        armed = self._armed
        if armed is None and self._follow is not None:
            armed = self._follow()
        return armed

    def blocked_for(self) -> float:
        """How long the call under way has run [s]; 0 when none is."""
        armed = self._under_way()
        return time.monotonic() - armed[3] if armed else 0.0

    def end(self, status: str, reason: str) -> None:
        """End the run from this thread (once): the loop's thread is not coming back."""
        if self._fired:
            return
        self._fired = True
        self.on_stuck(status, reason)

    def _watch(self) -> None:
        while not self._stop.wait(self.poll):
            armed = self._under_way()
            if armed is None:
                continue
            what, time_s, deadline, since, cause = armed
            if time.monotonic() - since > deadline:
                self.end(
                    "failed",
                    f"{what} [DEADLINE_EXCEEDED]: no answer within {deadline:g} s; "
                    + cause.format(time=time_s),
                )
                return
