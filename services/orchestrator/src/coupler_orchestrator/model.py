"""The run's data types, one name per concept, in the order the pipeline makes them.

Nothing here does anything: each stage reads what the one before made and makes the next
(docs/orchestrator.md, "How a run flows"):

    (its dialect) -> Semantics   (how the stages read it where a dialect differs: chosen once)
    participants -> Roster of Candidates   (2: each component's participant, described)
    checks       -> Checked: TimeGrid, Members, Routes   (3: what passed every check)
    wiring       -> Links   (4: one converter per connection)
    plan         -> Plan    (6: what the master executes)

It imports nothing heavy at run time, so that the command line can name the choices.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Protocol

from coupler.channels import Channel, Description, Value
from coupler.grid import decimal_of

if TYPE_CHECKING:
    from coupler.participant import Participant
    from coupler_orchestrator import ssp
    from coupler_orchestrator.observer import RunEnd


class Algorithm(StrEnum):
    """Master algorithms."""

    JACOBI = "jacobi"
    GAUSS_SEIDEL = "gauss-seidel"


@dataclass(frozen=True, kw_only=True)
class Candidate:
    """One component and the participant that fills it, as it described itself: a member of
    the run once the checks pass (``Member``)."""

    component: ssp.Component
    participant: Participant
    description: Description | None
    """What the participant declared; None when it could not be opened or described."""
    units: Mapping[str, ssp.BaseUnit] = field(default_factory=dict)
    """Units the participant defines itself (an FMU's UnitDefinitions), by name."""

    @property
    def name(self) -> str:
        return self.component.name


@dataclass(frozen=True, kw_only=True)
class Roster:
    """Every component's candidate, in scenario order, and what went wrong filling them."""

    candidates: Mapping[str, Candidate]
    problems: tuple[str, ...] = ()

    def described(self) -> dict[str, Description]:
        """Descriptions of the participants that could be described."""
        return {n: s.description for n, s in self.candidates.items() if s.description is not None}


@dataclass(frozen=True, kw_only=True)
class TimeGrid:
    """Communication points: t_k is the double nearest to the exact decimal start + k * step.

    ``start`` and ``step`` are read as the decimals the user wrote (the shortest text that reads
    back to each double: ``0.1`` is 1/10, not 0.1000000000000000055...), and t_k is computed
    exactly, by integers, then rounded once: a 0.1 s grid gives 0.3, never the
    0.30000000000000004 that 3 * 0.1 or 0.1 + 0.1 + 0.1 would.
    """

    start: float
    """t_0 [s]."""
    step: float
    """Base communication step h [s]."""
    steps: int
    """Number of base steps; the last point is ``time(steps)``."""
    _origin: int = field(init=False, repr=False, compare=False)
    _stride: int = field(init=False, repr=False, compare=False)
    _scale: int = field(init=False, repr=False, compare=False)
    """t_k = (_origin + k * _stride) / _scale, in integers until the one rounding division."""

    def __post_init__(self) -> None:
        start, step = decimal_of(self.start), decimal_of(self.step)
        scale = math.lcm(start.denominator, step.denominator)
        object.__setattr__(self, "_origin", start.numerator * (scale // start.denominator))
        object.__setattr__(self, "_stride", step.numerator * (scale // step.denominator))
        object.__setattr__(self, "_scale", scale)

    def time(self, k: int) -> float:
        """t_k: the double nearest to start + k * step (Python's int / int rounds correctly)."""
        return (self._origin + k * self._stride) / self._scale

    @property
    def stop(self) -> float:
        return self.time(self.steps)

    def in_doubles(self) -> tuple[float, float, float] | None:
        """(origin, stride, scale) as doubles when they and every numerator up to the last
        point's are integers below 2**53: then (origin + k * stride) / scale computed in
        doubles is ``time(k)`` (each operand exact, the one division correctly rounded, as
        Python's int / int is); else None."""
        exact = 2**53
        last = abs(self._origin) + (self.steps + 1) * abs(self._stride)
        if last >= exact or self._scale >= exact:
            return None
        return float(self._origin), float(self._stride), float(self._scale)


@dataclass(frozen=True, kw_only=True)
class Member:
    """One participant of the run, as checked."""

    name: str
    """Component name in the scenario."""
    participant: Participant
    """Local (FMU) or remote; the master cannot tell."""
    outputs: tuple[Channel, ...] = ()
    """Outputs recorded, in column order."""
    multiple: int = 1
    """Steps every ``multiple`` base steps (per-component deltaTime = multiple x h)."""
    step: float
    """The step size it receives, exactly as configured: its deltaTime, else h [s]."""
    deadline: float = 30.0
    """Deadline of each of its calls [s]: its callTimeout setting, else --call-timeout."""
    parameters: Mapping[str, Value] = field(default_factory=dict)
    """Parameter values sent with Initialize, typed."""
    start_inputs: Mapping[str, Value] = field(default_factory=dict)
    """Start values of inputs sent with Initialize, typed."""


@dataclass(frozen=True, kw_only=True)
class Route:
    """One connection, checked: the channels at both ends and the unit conversion between."""

    connection: ssp.Connection
    source: Channel
    """The output (as the participant declares it) that drives the connection."""
    target: Channel
    """The input it drives."""
    conversion: Conversion | None = None
    """Unit conversion from the source's unit to the target's; None when there is none."""
    source_enum: ssp.Enumeration | None = None
    """The SSD enumeration of the start connector (Enumeration connectors)."""
    target_enum: ssp.Enumeration | None = None
    """The SSD enumeration of the end connector."""


@dataclass(frozen=True, kw_only=True)
class Checked:
    """A scenario that passed every check, and what the checks established."""

    scenario: ssp.Scenario
    grid: TimeGrid
    algorithm: Algorithm
    members: tuple[Member, ...]
    """In scenario order."""
    routes: tuple[Route, ...]
    record_every: int = 1
    """Results record every ``record_every``-th communication point (``--output-interval``)."""
    warnings: tuple[str, ...]
    """The scenario's warnings and the checks' own (units nobody understands)."""
    semantics: Semantics
    """How the run reads the scenario (Coupler's, or a dialect's: OpenMCx's)."""
    cut: frozenset[str] = frozenset()
    """The connections the semantics cut to break algebraic loops, by driven input
    (``Component.connector``): the target reads the source's value of the step before."""


Converter = Callable[[Value], Value]
Conversion = Callable[[float], float]
"""A unit conversion (``ssp.units``)."""


class Semantics(Protocol):
    """How the stages read a scenario where a dialect reads it otherwise than Coupler does:
    one object, chosen once before the checks (``pipeline.openmcx.semantics_of``). The generic
    stages ask it and never name a dialect; Coupler's own is ``pipeline.semantics.COUPLER``,
    OpenMCx's translates its annotations (``pipeline.openmcx``)."""

    name: str
    """What summary.json calls it (``semantics``)."""
    checks_units: bool
    """Each SSD connector's unit is compared with its participant's, and a connection converts
    by SSP's unit algebra (refusing units of another dimension); False: ``conversion`` does."""
    whole_run: bool
    """A member's deltaTime must divide the run; False: it may step past the stop time."""

    def conversion(
        self, scenario: ssp.Scenario, start: ssp.Connector | None, end: ssp.Connector | None
    ) -> Conversion | None:
        """A connection's unit conversion when ``checks_units`` is False."""
        ...

    def start_inputs(self, scenario: ssp.Scenario, component: ssp.Component) -> dict[str, Value]:
        """Start values the scenario gives inputs of ``component`` beyond its bindings."""
        ...

    def entering(self, connector: ssp.Connector) -> Converter | None:
        """What the input ``connector`` does to a value entering it; None: nothing."""
        ...

    def cut_loops(self, scenario: ssp.Scenario, algorithm: Algorithm) -> frozenset[str]:
        """The connections cut to break loops (``Checked.cut``); ValidationError naming every
        loop the algorithm cannot order."""
        ...

    def order(self, checked: Checked, links: Sequence[Link]) -> tuple[str, ...]:
        """The members' names in the order they initialize and step."""
        ...

    def additions(self, checked: Checked, links: tuple[Link, ...]) -> OpenMcx | None:
        """What the semantics add to the plan (``Plan.openmcx``); None: nothing."""
        ...


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
    """Widening, unit conversion and transformation; None is identity."""
    decoupled: bool = False
    """Gauss-Seidel may break a loop here (the target may see the previous step's value)."""

    @property
    def label(self) -> str:
        return f"{self.source}.{self.output} -> {self.target}.{self.input}"


@dataclass(frozen=True, kw_only=True)
class Filtering:
    """How the target of one connection reads it with OpenMCx's semantics (``master.filters``)."""

    extrapolation: int = 0
    """Order of the extrapolation over the source's committed points (0 holds the last)."""
    interpolation: int | None = None
    """Order of the interpolation between the points the source wrote; None: extrapolation
    only."""


@dataclass(frozen=True, kw_only=True)
class OpenMcx:
    """What OpenMCx's semantics add to a plan (docs/openmcx.md)."""

    sequential: bool
    """stepType sequential: each member, in ``order``, reads what the members before it
    committed in the same step (Gauss-Seidel); else all read the last step's (Jacobi)."""
    order: tuple[str, ...]
    """OpenMCx's evaluation order, loops cut: the order members initialize and step in."""
    first_component: bool = False
    """endType first_component: the run ends after the step in which a member finished; else a
    finished member stops stepping and the others go on."""
    eps: float
    """OpenMCx's time comparison tolerance: relativeEps * h."""
    filters: Mapping[tuple[str, str], Filtering] = field(default_factory=dict)
    """Per connection, by (target, input)."""
    initial: Mapping[tuple[str, str], Value] = field(default_factory=dict)
    """The value a cut connection carries during initialization, by (target, input)."""
    input_at_end: frozenset[str] = frozenset()
    """Members that read their inputs at the end of each of their steps."""
    own_time: frozenset[str] = frozenset()
    """Members with their own step (``deltaTime``): OpenMCx keeps their time as a running sum,
    and reads and writes their connections at that time."""
    sub_steps: Mapping[str, int] = field(default_factory=dict)
    """Members stepped in sub-steps whose inputs are read again (the Integrator's)."""
    outputs: Mapping[str, Mapping[str, Converter]] = field(default_factory=dict)
    """What each member's OpenMCx output ports do to its outputs, by member and channel."""


@dataclass(frozen=True, kw_only=True)
class Plan:
    """Everything the master needs."""

    members: tuple[Member, ...]
    """In scenario order (the order of results columns)."""
    order: tuple[Member, ...]
    """The same members in the order the algorithm steps them."""
    links: tuple[Link, ...]
    """Every connection."""
    grid: TimeGrid
    """The communication points."""
    algorithm: Algorithm
    """Master algorithm."""
    run_id: str
    """Identifies the run in logs, participants and results; unique per run."""
    run_secret: bytes = field(repr=False)
    """Authenticates the run's calls at its participants (``RunOptions.run_secret``)."""
    lease: float
    """Lease granted with Initialize [s]: a participant ends the run after this long without a
    call."""
    realtime_factor: float | None = None
    """Pace simulated time at this multiple of wall time; None runs as fast as possible."""
    on_abandoned: Callable[[RunEnd], None] | None = None
    """Told when the run is abandoned, its thread stuck (``RunOptions.on_abandoned``)."""
    progress: memoryview | None = field(default=None, compare=False, repr=False)
    """Where the native FMU step keeps the step under way (``RunOptions.progress``)."""
    native: bool = False
    """Step in-process FMUs in C when the plan allows it (``master.native_fmu_step``)."""
    openmcx: OpenMcx | None = None
    """What OpenMCx's semantics add (``Semantics.additions``), run by ``master.openmcx``; None:
    Coupler's."""
