"""The run-time plan the master algorithm executes: members, links and the time grid.

Built from a parsed scenario by ``coupler_orchestrator.planning``; nothing here knows SSP.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum

from coupler.channels import Channel, Value
from coupler.errors import ScenarioError
from coupler.participant import Participant

Converter = Callable[[Value], Value]


class Algorithm(StrEnum):
    """Master algorithms."""

    JACOBI = "jacobi"
    GAUSS_SEIDEL = "gauss-seidel"


@dataclass(frozen=True, kw_only=True)
class Member:
    """One participant of the run."""

    name: str
    """Component name in the scenario."""
    participant: Participant
    """Local (FMU) or remote; the master cannot tell."""
    outputs: tuple[Channel, ...] = ()
    """Outputs recorded, in column order."""
    multiple: int = 1
    """Steps every ``multiple`` base steps (per-component deltaTime = multiple x h)."""
    parameters: Mapping[str, Value] = field(default_factory=dict)
    """Parameter values sent with Initialize."""
    start_inputs: Mapping[str, Value] = field(default_factory=dict)
    """Start values of inputs sent with Initialize."""


@dataclass(frozen=True, kw_only=True)
class Link:
    """One connection: an output feeding an input, converted on the way."""

    source: str
    """Component that writes."""
    output: str
    """Its output channel."""
    target: str
    """Component that reads."""
    input: str
    """Its input channel."""
    convert: Converter | None = None
    """Unit conversion and transformation; None is identity."""
    decoupled: bool = False
    """Gauss-Seidel may break a loop here (the target sees the previous step's value)."""

    @property
    def label(self) -> str:
        return f"{self.source}.{self.output} -> {self.target}.{self.input}"


@dataclass(frozen=True, kw_only=True)
class TimeGrid:
    """Communication points t_k = start + k * step, computed by multiplication, never summed."""

    start: float
    """t_0 [s]."""
    step: float
    """Base communication step h [s]."""
    steps: int
    """Number of base steps; the last point is start + steps * step."""

    @classmethod
    def between(cls, start: float, stop: float, step: float) -> TimeGrid:
        """The grid from start to stop; stop must be reached by whole steps."""
        if not step > 0:
            raise ScenarioError(f"step size must be positive, got {step:g} s (give --step H)")
        if not stop > start:
            raise ScenarioError(f"stop time {stop:g} s must be after start time {start:g} s")
        ratio = (stop - start) / step
        steps = round(ratio)
        if not math.isclose(ratio, steps, rel_tol=1e-9, abs_tol=1e-9):
            raise ScenarioError(
                f"stop time {stop:g} s is not start {start:g} s plus a whole number of steps of "
                f"{step:g} s ({ratio:.6g} steps); choose a step that divides the interval"
            )
        return cls(start=start, step=step, steps=steps)

    def time(self, k: int) -> float:
        return self.start + k * self.step

    @property
    def stop(self) -> float:
        return self.time(self.steps)


@dataclass(frozen=True, kw_only=True)
class Plan:
    """Everything the master needs."""

    members: tuple[Member, ...]
    """In scenario order (Jacobi) or topological order (Gauss-Seidel)."""
    links: tuple[Link, ...]
    """Every connection."""
    grid: TimeGrid
    """The communication points."""
    algorithm: Algorithm = Algorithm.JACOBI
    """Master algorithm."""
    run_id: str
    """Identifies the run in logs, participants and results; unique per run."""
    lease: float = 0.0
    """Lease granted with Initialize [s]: a participant ends the run after this long without
    a call (0: the participant's default)."""
    realtime_factor: float | None = None
    """Pace simulated time at this multiple of wall time; None runs as fast as possible."""
