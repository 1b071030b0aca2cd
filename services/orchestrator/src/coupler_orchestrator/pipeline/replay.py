"""``ReplayParticipant``: a recording (``coupler_orchestrator.recording``) served again as the
participant it recorded — in-process for an SSD source ``replay:PATH#Component`` or
``coupler run --replay COMPONENT=PATH``, or over gRPC with ``coupler replay PATH``.

It declares the recorded channels and answers each step with the recorded outputs of the time
the step reaches, bit for bit. Its inputs and parameters are accepted and ignored: a replay
does not depend on what the rest of the run sends it. A run whose start time, step or stop
time the recording does not have is refused at Initialize (and by ``coupler validate``/the
checks, for an in-process replay), naming the recorded grid. When the recorded participant
asked to end the run, the replay asks again at the same point, with the same reason.
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

from coupler.channels import Description, RunSetup, Value
from coupler.errors import ScenarioError
from coupler.participant import EndRun, Participant, Values
from coupler_orchestrator.recording import Points, Recording, locate, read
from coupler_orchestrator.ssp import REPLAY_SCHEME as SCHEME


def parse_source(source: str) -> tuple[Path, str | None]:
    """``replay:PATH#Component`` as (PATH, Component); the component part is optional."""
    path, _, component = source.removeprefix(SCHEME).partition("#")
    if not path:
        raise ScenarioError(
            f"source '{source}' names no recording; write replay:PATH#Component, PATH a .crec "
            f"file or a results directory"
        )
    return Path(path), component or None


class ReplayParticipant(Participant):
    """Serves the recording at ``path`` (a .crec file or a directory holding
    ``recordings/COMPONENT.crec``) of ``component`` (default: whichever the file holds)."""

    def __init__(self, path: Path, component: str | None = None, *, name: str = "") -> None:
        self.path = path
        self.component = component
        """The recorded component asked for; None: whichever the file holds."""
        self.name = name or component or ""
        """The component it stands in for (a directory's recording of that name is used)."""
        self._recording: Recording | None = None
        self._points: Points | None = None
        """The recorded points, read one block at a time."""

    @property
    def recording(self) -> Recording:
        if self._recording is None:
            raise ScenarioError(f"the recording {self.path} is not open yet")
        return self._recording

    async def open(self) -> None:
        if self._recording is not None:
            return
        file = locate(self.path, self.component or self.name or None)
        recording = await asyncio.to_thread(read, file)
        if self.component is not None and recording.component != self.component:
            raise ScenarioError(
                f"{file} is a recording of '{recording.component}', not of '{self.component}'; "
                f"write replay:{self.path}#{recording.component} or pick the right file"
            )
        self._recording = recording
        self._points = recording.points()

    async def close(self) -> None:
        if self._points is not None:
            self._points.close()
            self._points = None
        self._recording = None

    async def describe(self) -> Description:
        await self.open()
        recording = self.recording
        recorded = recording.description
        return replace(
            recorded,
            implementation=(
                f"coupler replay of {recorded.implementation or recorded.name} "
                f"({recording.summary().partition(' has ')[2]})"
            ),
        )

    def grid_problem(self, start: float, step: float, stop: float | None) -> str | None:
        """Why a run with these times cannot be replayed, or None (see ``Recording``)."""
        return self.recording.grid_problem(start, step, stop)

    async def initialize(self, setup: RunSetup) -> Values:
        problem = self.grid_problem(setup.start_time, setup.step_size, setup.stop_time)
        if problem is not None:
            raise ScenarioError(problem)
        return await self._outputs_at(0)

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        recording = self.recording
        j = recording.point(time, step)
        outputs = await self._outputs_at(j)
        if j == recording.steps and recording.request is not None:
            raise EndRun(recording.request, outputs)  # as the recorded participant did
        return outputs

    async def terminate(self, reason: str = "") -> None:
        return None

    async def _outputs_at(self, j: int) -> Values:
        """The recorded outputs of point j; a new block is read off the event loop."""
        points = self._points
        if points is None:
            raise ScenarioError(f"the recording {self.path} is not open")
        if not points.holds(j):
            await asyncio.to_thread(points.at, j)
        return dict(points.at(j))
