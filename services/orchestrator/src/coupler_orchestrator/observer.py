"""What a run tells its observers: the CSV recorder, the summary, the progress display, live
views and tests all see the same events, in this order: ``started``, then ``stepped`` (and
``timed``) for every communication point from t_0 on, then ``closing`` and ``finished`` — on
every path.
Where the master takes several base steps in one call into C (the native FMU step), it tells
their points together, in order (``stepped_batch``, which by default calls ``stepped`` and
``timed`` for each); a batch spans at most a few hundred steps and a fiftieth of a second.

Observers are called on the event loop and must not block long; an observer that cannot do its
job (a full disk) raises a CouplerError, which ends the run as ``failed`` with that reason.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from coupler.channels import Value


@dataclass(frozen=True, kw_only=True)
class Column:
    """One recorded output."""

    name: str
    """``Component.connector``."""
    unit: str
    """Unit symbol, empty when none."""
    type: str
    """Value type name (Real, Integer, ...)."""
    message_type: str = ""
    """Binary columns: the protobuf message carried, when the participant names one."""


@dataclass(frozen=True, kw_only=True)
class RunInfo:
    """What observers learn when a run starts."""

    run_id: str
    """The run's id."""
    algorithm: str
    """Master algorithm."""
    members: tuple[str, ...]
    """Component names, in scenario order (the order of ``timed``'s samples)."""
    multiples: tuple[int, ...]
    """Each member's step multiple, aligned with ``members``."""
    columns: tuple[Column, ...]
    """Recorded outputs, in row order."""
    start_time: float
    """t_0 [s]."""
    stop_time: float
    """Last communication point planned [s]."""
    step_size: float
    """Base step h [s]."""
    steps: int
    """Number of base steps planned."""


@dataclass(frozen=True, kw_only=True)
class RunEnd:
    """How a run ended."""

    status: str
    """``completed``, ``terminated`` (a participant asked to end it), ``failed`` or
    ``aborted`` (interrupted)."""
    reason: str
    """Why it ended so; empty when completed."""
    steps: int
    """Base steps completed."""
    end_time: float
    """Last communication point recorded [s]."""
    wall_time: float
    """Wall-clock duration from the start of initialization [s]."""
    ended_by: str = ""
    """``terminated``: the component that asked to end the run; else empty."""
    request: str = ""
    """``terminated``: the reason that component gave, as it gave it."""
    step_paths: Mapping[str, StepPath] = field(default_factory=dict)
    """How each member stepped, by name (empty when the run ended before its first step)."""


@dataclass(frozen=True)
class StepPath:
    """How a member stepped, and why that way."""

    path: str
    """``native FMU step`` (in C, with every other member), ``native step channel`` (its
    StepStream over C++ gRPC) or ``Python``."""
    reason: str


class Steps(Protocol):
    """Consecutive communication points told at once (``Observer.stepped_batch``)."""

    times: Sequence[float]
    """Each point's time, in order."""
    log: Any
    """Where the points were read from: the native FMU step's row log
    (``coupler_native._rows.RowLog``, whose rows results.csv's lines are made of in C)."""

    def row(self, j: int) -> Sequence[Value]:
        """The outputs at ``times[j]``, as ``stepped`` would have been told them."""
        ...

    def seconds(self, j: int) -> Sequence[float | None]:
        """What ``timed`` would have been told after the step to ``times[j]``."""
        ...

    def samples(self, member: int) -> Sequence[float]:
        """The step latencies of ``RunInfo.members[member]`` over these points [s]."""
        ...


class Observer:
    """Override what you need."""

    def started(self, info: RunInfo) -> None:
        """The run begins (before the participants are initialized)."""

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        """Outputs at communication point ``time``, aligned with ``RunInfo.columns``."""

    def timed(self, seconds: Sequence[float | None]) -> None:
        """How long each member's step just taken lasted [s], aligned with ``RunInfo.members``;
        None for a member that was not due."""

    def costed(self, seconds: Sequence[float | None], waited: Sequence[float | None]) -> None:
        """What each member's step just taken cost the member itself [s], aligned with
        ``RunInfo.members`` (after ``timed``): its own account (a remote participant's
        ``DoStepResponse.step_seconds``; a step computed in this process: its latency), and
        how much of that it waited for an outside program it fronts (``waited_seconds``);
        None for a member that was not due or did not say."""

    def stepped_batch(self, steps: Steps) -> None:
        """Several communication points at once, in order: ``stepped`` (and ``timed`` and
        ``costed``, when overridden) for each, by default. Override it where one call for all
        of them does the same in less time. (Every member of such a batch computes in this
        process: its cost is its latency.)"""
        timed = type(self).timed is not Observer.timed
        costed = type(self).costed is not Observer.costed
        for j, time in enumerate(steps.times):
            self.stepped(time, steps.row(j))
            if timed or costed:
                seconds = steps.seconds(j)
                if timed:
                    self.timed(seconds)
                if costed:
                    self.costed(seconds, [None] * len(seconds))

    def closing(self, end: RunEnd) -> None:
        """The run has ended (``end``, as far as the steps go): write what is still buffered.
        A recorder that cannot (a full disk) raises a CouplerError saying which file and what
        it keeps; the run then ends ``failed`` with that reason, and ``finished`` says so to
        every observer. Called for every observer before any is told ``finished``."""

    def finished(self, end: RunEnd) -> None:
        """The run ended, however it ended (after every observer's ``closing``)."""


class ComponentObserver(Observer):
    """An observer that also sees each member's own steps, as a run with OpenMCx's semantics
    makes them (a member with its own step is told at its own times only)."""

    def component_inputs(self, component: str, time: float, values: Mapping[str, Value]) -> None:
        """The inputs ``component`` read for its step from (or, reading at the end of its
        steps, to) ``time``, by channel."""

    def component_outputs(self, component: str, time: float, values: Mapping[str, Value]) -> None:
        """Its outputs at ``time``, the end of a step (or the start time), by channel."""
