"""How each member steps: one object per member, chosen once after Initialize by one function
(``steppers_of``), which records why (what summary.json reports). The loops only ``begin`` and
``finish`` steps (mosaik's simulator proxies; FMPy's loop on one screen):

- ``InProcess``: an in-process FMU (``FmuParticipant.step_now``) or an OpenMCx built-in
  computes on the master's thread in ``finish``, where a hop to another thread would cost more
  than its step, watched against its deadline (the watchdog ends the run past it);
- ``InHalves``: a remote participant on the native step channel (``native_step_channel``):
  ``begin`` sends its request, ``finish`` waits for the answer on the master's thread (watched),
  so many requests are on their way while the master computes what it computes itself;
- ``Awaited``: every other participant, through ``Participant.do_step``: ``begin`` puts the
  call in flight (``landing``), ``finish`` takes its answer once it has landed.

A run of in-process FMUs only is stepped whole by the native FMU batch (``native_fmu_step``),
every member at once in C.

Each stepper notes how long the member's last step took as the master saw it (``took``: its
latency) and what it cost the member itself (``cost``, ``waited``): a step computed here costs
its latency; a remote participant says what its step cost (``DoStepResponse.step_seconds``).
On the native step channel the master receives the answers one after another, after it has
sent every request, so a member's latency holds the wait for the members received before it;
its cost does not (summary.json reports both).

Every way has the meaning and the errors of ``Participant.do_step``: ``finish`` returns the
outputs, or raises what the participant raised (``EndRun``: it asks to end the run).
"""

from __future__ import annotations

import asyncio
import contextlib
import time as wallclock
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping
from typing import Protocol, runtime_checkable

from coupler.channels import Value
from coupler.participant import Participant, Values
from coupler.wire import StepCost
from coupler_orchestrator.master import native_fmu_step, native_step_channel
from coupler_orchestrator.master.watchdog import IN_PROCESS, Watchdog
from coupler_orchestrator.model import Member, Plan
from coupler_orchestrator.observer import StepPath

NATIVE_STUCK = (
    "the native step channel did not come back from its own deadline (the run had reached "
    "t={time:g} s); run with --no-native-steps and report it"
)
"""What a split step's answer past its deadline (and the channel's own) means."""


class Halves(Protocol):
    """A step taken in two halves on the caller's thread: ``send`` the request, ``receive`` the
    answer (blocking until it is there or the call deadline has passed)."""

    described: tuple[str, str]
    """How summary.json names this way of stepping (``StepPath``), and why."""
    reported: StepCost
    """What the last answer received said its step cost the participant."""

    def send(self, time: float, step: float, inputs: Mapping[str, Value]) -> None: ...

    def receive(self) -> Values: ...


@runtime_checkable
class StepsHere(Protocol):
    """A participant that computes in the orchestrator's process (an in-process FMU, an
    OpenMCx built-in) and can step on the caller's thread, never waiting on anything."""

    def step_now(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values: ...


@runtime_checkable
class Reports(Protocol):
    """A participant whose answers say what each step cost it (``RemoteParticipant``)."""

    reported: StepCost
    """What the last step's answer said the step cost the participant."""


@runtime_checkable
class StepsInHalves(Protocol):
    """A participant whose transport may take its steps in two halves (``RemoteParticipant``:
    its transport's ``split``)."""

    def split(self) -> Halves | None: ...


class Stepper(ABC):
    """How one member steps: ``begin`` a step, then ``finish`` it; when ``begin`` leaves
    ``landing``, the answer arrives on the event loop and is awaited before ``finish``."""

    path: StepPath
    """How summary.json names this way of stepping, and why it is this one."""
    landing: asyncio.Future[Values] | None = None
    """The answer under way on the event loop (``Awaited``); None: ``finish`` gives it here."""
    took: float = 0.0
    """How long the last step took [s] (the member's latency)."""
    cost: float | None = None
    """What the last step cost the member itself [s]; None: not said."""
    waited: float | None = None
    """Of ``cost``, the time the member waited for an outside program [s]; None: not said."""
    here: bool = True
    """Its steps run or are waited for on the master's thread (watched by the watchdog)."""

    @abstractmethod
    def begin(self, time: float, step: float, inputs: Values) -> None:
        """Start the step from ``time`` by ``step`` with ``inputs``."""

    @abstractmethod
    def finish(self) -> Values:
        """The outputs of the step begun (after ``landing``, if any, has landed)."""

    async def whole(self, time: float, step: float, inputs: Values) -> Values:
        """A step begun and finished at once (Gauss-Seidel, OpenMCx's master)."""
        self.begin(time, step, inputs)
        return self.finish()

    def held(self, time: float) -> contextlib.AbstractContextManager[None]:
        """Several calls held to one deadline, from simulated ``time`` (OpenMCx's sub-steps of
        one step); each call is watched alone otherwise."""
        return contextlib.nullcontext()


class Watched(Stepper):
    """A stepper whose calls run or are waited for on the master's thread, watched against
    the member's deadline by the run's watchdog."""

    def __init__(self, watchdog: Watchdog, member: Member, deadline: float, cause: str) -> None:
        self._watchdog = watchdog
        self._what = f"{member.name}.DoStep"
        self._deadline = deadline
        self._cause = cause
        """What a call past its deadline means."""
        self._holding = False
        """Inside ``held``: its calls are watched by the one arming of ``held``."""

    @contextlib.contextmanager
    def _held(self, time: float) -> Iterator[None]:
        self._watchdog.arm(self._what, time, self._deadline, self._cause)
        self._holding = True
        try:
            yield
        finally:
            self._holding = False
            self._watchdog.disarm()

    def held(self, time: float) -> contextlib.AbstractContextManager[None]:
        return self._held(time)


class InProcess(Watched):
    """Computes on the master's thread in ``finish``, watched against its deadline (past it,
    the participant's ``overrun`` says what it means)."""

    def __init__(
        self,
        step_now: Callable[[float, float, Mapping[str, Value]], Values],
        watchdog: Watchdog,
        member: Member,
        *,
        overrun: str,
        path: StepPath,
    ) -> None:
        super().__init__(watchdog, member, member.deadline, overrun)
        self._step_now = step_now
        self._call: tuple[float, float, Values] = (0.0, 0.0, {})
        self.path = path

    def begin(self, time: float, step: float, inputs: Values) -> None:
        self._call = (time, step, inputs)

    def finish(self) -> Values:
        time, step, inputs = self._call
        started = wallclock.perf_counter()
        if not self._holding:
            self._watchdog.arm(self._what, time, self._deadline, self._cause)
        try:
            return self._step_now(time, step, inputs)
        finally:
            if not self._holding:
                self._watchdog.disarm()
            self.took = self.cost = wallclock.perf_counter() - started


class InHalves(Watched):
    """Sends its request in ``begin``; waits for the answer on the master's thread in
    ``finish`` (watched: past the call deadline the channel itself gives up; 10 s after it, the
    watchdog ends the run)."""

    def __init__(self, halves: Halves, watchdog: Watchdog, member: Member) -> None:
        super().__init__(watchdog, member, member.deadline + 10, NATIVE_STUCK)
        self._halves = halves
        self._time = 0.0
        self._sent = 0.0
        self.path = StepPath(*halves.described)

    def begin(self, time: float, step: float, inputs: Values) -> None:
        self._time = time
        self._sent = wallclock.perf_counter()
        self._halves.send(time, step, inputs)

    def finish(self) -> Values:
        if not self._holding:
            self._watchdog.arm(self._what, self._time, self._deadline, self._cause)
        try:
            return self._halves.receive()
        finally:
            if not self._holding:
                self._watchdog.disarm()
            self.took = wallclock.perf_counter() - self._sent
            self.cost, self.waited = self._halves.reported


class Awaited(Stepper):
    """``Participant.do_step``, awaited: in flight from ``begin`` (``landing``) until
    ``finish``, or awaited at once (``whole``)."""

    here = False

    def __init__(self, participant: Participant, path: StepPath) -> None:
        self._participant = participant
        self._reports = participant if isinstance(participant, Reports) else None
        self.path = path

    def begin(self, time: float, step: float, inputs: Values) -> None:
        self.landing = asyncio.ensure_future(self.whole(time, step, inputs))

    def finish(self) -> Values:
        landing = self.landing
        assert landing is not None and landing.done(), "finish before the answer landed"
        self.landing = None
        return landing.result()

    async def whole(self, time: float, step: float, inputs: Values) -> Values:
        started = wallclock.perf_counter()
        try:
            return await self._participant.do_step(time, step, inputs)
        finally:
            self.took = wallclock.perf_counter() - started
            if self._reports is not None:
                self.cost, self.waited = self._reports.reported


def steppers_of(
    plan: Plan, watchdog: Watchdog
) -> tuple[dict[str, Stepper], native_fmu_step.Kernel | None, dict[str, StepPath]]:
    """How every member of ``plan`` steps (after Initialize), decided here only: the native FMU
    batch when the plan allows it (every member at once in C), else a stepper per member; and
    how and why each steps that way (summary.json's ``step_paths``)."""
    kernel, why = native_fmu_step.prepare(plan)
    if kernel is not None:
        path = StepPath("native FMU step", why)
        return {}, kernel, {m.name: path for m in plan.order}
    steppers = {m.name: stepper_of(m, plan, watchdog, why) for m in plan.order}
    return steppers, None, {name: s.path for name, s in steppers.items()}


def stepper_of(member: Member, plan: Plan, watchdog: Watchdog, kernel_reason: str) -> Stepper:
    """The way ``member`` steps in this run, and why (``kernel_reason``: why not in C)."""
    participant = member.participant
    if isinstance(participant, StepsHere):
        overrun = getattr(participant, "overrun", IN_PROCESS)
        path = StepPath("Python", f"in-process; not in C: {kernel_reason}")
        return InProcess(participant.step_now, watchdog, member, overrun=overrun, path=path)
    if isinstance(participant, StepsInHalves) and (halves := participant.split()) is not None:
        return InHalves(halves, watchdog, member)
    why = native_step_channel.why_python(participant, plan.native)
    return Awaited(participant, StepPath("Python", why))
