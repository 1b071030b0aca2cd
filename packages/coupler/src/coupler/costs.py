"""What a step costs the participant itself, as its runtime reports it in every answer.

The orchestrator sees how long it waited for each answer; when it waits for several
participants at once, or a step's request and answer cross a network, that says little about
the participant's own work. So the participant runtime measures each step around the
participant's ``do_step`` (``StepMeter``) and sends the figure with the outputs
(``DoStepResponse.step_seconds``); summary.json reports it per participant (``step_cost_ms``).

A participant that fronts another program (a bridge to a simulator it calls over HTTP) marks
the time it waits for that program with ``waiting()``; that part of the step is reported too
(``DoStepResponse.waited_seconds``, summary.json ``waited_ms``)::

    async def advance(self, time: float, step: float) -> None:
        with waiting():
            await self.client.post("/step")  # the simulator's own time
"""

from __future__ import annotations

import contextlib
import time as wallclock
from collections.abc import Iterator
from contextvars import ContextVar

_WAITED: ContextVar[list[float] | None] = ContextVar("coupler_waited", default=None)
"""The running step's waits [s] (one cell), while the runtime measures a step."""


@contextlib.contextmanager
def waiting() -> Iterator[None]:
    """The time inside this block is part of the running step spent waiting for an outside
    program the participant fronts. Waits that overlap (concurrent tasks) add up: mark the
    wait once, around all of it. Outside a step the runtime measures, nothing is counted."""
    started = wallclock.perf_counter()
    try:
        yield
    finally:
        waited = _WAITED.get()
        if waited is not None:
            waited[0] += wallclock.perf_counter() - started


class StepMeter:
    """Measures one step: ``start`` before the participant's ``do_step``, ``stop`` after it;
    then ``seconds`` and ``waited`` hold what the step cost and how much of it was waited.
    One meter per step loop (a step stream, a step socket) or call."""

    __slots__ = ("_cell", "_started", "_token", "seconds", "waited")

    def __init__(self) -> None:
        self._cell = [0.0]
        self._started = 0.0
        self._token: object = None
        self.seconds = 0.0
        self.waited = 0.0

    def start(self) -> None:
        self._cell[0] = 0.0
        self._token = _WAITED.set(self._cell)
        self._started = wallclock.perf_counter()

    def stop(self) -> None:
        """The step is over (again: nothing more)."""
        token, self._token = self._token, None
        if token is None:
            return
        self.seconds = wallclock.perf_counter() - self._started
        _WAITED.reset(token)  # type: ignore[arg-type]
        self.waited = min(self._cell[0], self.seconds)
