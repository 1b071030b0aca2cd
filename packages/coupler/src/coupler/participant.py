"""The one async interface every participant implements, local or remote.

The master algorithm, the gRPC server runtime and the client all speak it: an FMU run in-process
(``coupler.fmu.FmuParticipant``), a remote participant (``coupler.client.RemoteParticipant``)
and a simulator wrapped by an adapter (``coupler.adapter.AdapterParticipant``) look the same.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Awaitable, Callable, Mapping

from coupler.channels import Description, RunSetup, Value

Values = dict[str, Value]

HealthReport = Callable[[str | None], Awaitable[None]]
"""``await report(None)``: ready for a run (SERVING); ``await report(reason)``: not
(NOT_SERVING), with a reason a person can act on, carried by the health answers."""
HEALTH_REASON = "coupler-health-reason"
"""Trailing metadata of a NOT_SERVING health answer: the reason given to ``HealthReport``."""


class EndRun(Exception):
    """Raised by ``do_step``: the participant asks to end the run after this step.

    ``outputs`` are its outputs at the end of the step (the time reached); the orchestrator
    records them, terminates every participant and reports the run as ``terminated``. The
    same request travels over gRPC as ``DoStepResponse.terminate``.
    """

    def __init__(self, reason: str, outputs: Values) -> None:
        super().__init__(reason)
        self.reason = reason
        self.outputs = outputs


class Participant(ABC):
    """A co-simulation participant. One run at a time: initialize, do_step..., terminate."""

    @abstractmethod
    async def describe(self) -> Description:
        """The participant's channels and capabilities."""

    @abstractmethod
    async def initialize(self, setup: RunSetup) -> Values:
        """Start a run; return every output at ``setup.start_time``."""

    @abstractmethod
    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        """Advance from ``time`` by ``step`` with ``inputs``; return outputs at ``time + step``.

        Raise ``EndRun`` (with those outputs) to ask for the run to end after this step.
        """

    @abstractmethod
    async def terminate(self, reason: str = "") -> None:
        """End the run and free its resources; the participant may be initialized again."""

    async def open(self) -> None:  # noqa: B027 - optional hook, nothing to do by default
        """Get ready to serve: connect to the wrapped simulator, load files. Before describe."""

    async def close(self) -> None:  # noqa: B027 - optional hook, nothing to do by default
        """Release what the participant holds beyond a run (connections, processes)."""

    async def watch_health(self, report: HealthReport) -> None:
        """Called once open and described: say whether a run can start. A participant whose
        readiness changes (a wrapped simulator that is down, then up) keeps ``report`` and calls
        it again on every change. Default: ready."""
        await report(None)
