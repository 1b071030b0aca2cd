"""Stage 3: every check before anything runs, against the SSD and what the participants declare.

All problems are collected and raised together as one ValidationError, each a sentence naming
the file and line, the culprit and the fix. What passes becomes a ``Checked``: the time grid,
each member's settings and each connection's channels and unit conversion — the facts later
stages build on without checking again.

Checked here: the participants could be reached and described; connections join existing
connectors that can drive and be driven, one driver per input; every SSD connector exists on its
participant with the same causality, type and an equivalent unit; every input is driven, started
or bound; connected types are compatible (Integer widens to Real and travels as Enumeration;
anything else needs a transformation); units are compared across every connection from the best
source (the SSD connector's unit, else the participant's declared unit: an FMU's own unit
definitions, else the unit symbol) — convertible units are converted, units of another dimension
are refused, units nobody understands are warned about; transformations fit their ends; the
time grid is finite and reachable by whole steps; step multiples and fixed step sizes fit;
``--param`` values and parameter bindings name parameters or inputs and fit their types; no
output declares larger values than the input it drives accepts (``max_bytes``; declared maxima
together over ``--max-message-size`` are warned about); and every loop is one the algorithm
can order (Gauss-Seidel: broken by a decoupled connection, a component feeding itself
included).

Where a dialect reads the SSD otherwise (OpenMCx: units, loops, port defaults, a member
stepping past the stop time), the checks ask the run's ``Semantics``, chosen before them; they
never name a dialect.
"""

from __future__ import annotations

import difflib
import fnmatch
import math
from collections.abc import Callable, Mapping
from functools import partial
from typing import TypeVar

from coupler.channels import Causality, Channel, Description, Value, ValueType, fits_fixed_step
from coupler.errors import ChannelValueError, ScenarioError, ValidationError
from coupler.values import check as check_value
from coupler.values import parse, widen
from coupler_orchestrator import ssp
from coupler_orchestrator.model import (
    Algorithm,
    Candidate,
    Checked,
    Conversion,
    Member,
    Roster,
    Route,
    Semantics,
    TimeGrid,
)
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.pipeline.participants import where
from coupler_orchestrator.pipeline.replay import ReplayParticipant
from coupler_orchestrator.ssp.units import Affine, IncompatibleUnits, affine, from_symbol

T = TypeVar("T")
MAX_STEPS = 10**10
"""More communication points than this is a unit mistake, not a run."""
DEFAULT_STEP = 0.01
"""The step when neither the command line nor the SSD gives one: OpenMCx's default."""

#: Connected types that are compatible without a transformation: (output, input).
_COMPATIBLE = {
    (ValueType.INTEGER, ValueType.REAL),
    (ValueType.INTEGER, ValueType.ENUMERATION),
    (ValueType.ENUMERATION, ValueType.INTEGER),
}
_SOURCES = ("output", "calculatedParameter", "inout")
_SINKS = ("input", "parameter", "inout")
#: The end type each transformation needs (None: any numeric end, see _transformation).
_TRANSFORMED = {
    ssp.BooleanMappingTransformation: ValueType.BOOLEAN,
    ssp.IntegerMappingTransformation: ValueType.INTEGER,
    ssp.EnumerationMappingTransformation: ValueType.ENUMERATION,
}


def check(
    scenario: ssp.Scenario, roster: Roster, options: RunOptions, semantics: Semantics
) -> Checked:
    """Every check, reading the scenario with ``semantics``; ValidationError listing every
    problem, earlier stages' problems first."""
    checker = _Checker(scenario, roster, options, semantics)
    return checker.run()


class _Checker:
    def __init__(
        self, scenario: ssp.Scenario, roster: Roster, options: RunOptions, semantics: Semantics
    ) -> None:
        self.scenario = scenario
        self.roster = roster
        self.options = options
        self.semantics = semantics
        self.problems: list[str] = list(roster.problems)
        self.warnings: list[str] = list(scenario.warnings)

    def run(self) -> Checked:
        scenario = self.scenario
        for connection in scenario.connections:
            self.structure(connection)
        self.drivers()
        for candidate in self.roster.candidates.values():
            if candidate.description is not None:
                self.candidate(candidate, candidate.description)
                self.message_sizes(candidate, candidate.description)
        routes = [r for c in scenario.connections if (r := self.route(c)) is not None]
        grid = self.guard(lambda: grid_of(scenario, self.options))
        overrides = self.overrides()
        members = []
        for candidate in self.roster.candidates.values():
            if candidate.description is not None:
                member = self.guard(
                    partial(self.member, candidate, overrides.get(candidate.name, {}), grid)
                )
                if member is not None:
                    members.append(member)
        algorithm = self.options.algorithm or algorithm_of(scenario)
        cut = self.guard(lambda: self.semantics.cut_loops(scenario, algorithm)) or frozenset()
        record_every = self.recording(members, grid)
        if self.problems or grid is None:
            raise ValidationError(self.problems, subject=scenario.source.name)
        return Checked(
            scenario=scenario,
            grid=grid,
            algorithm=algorithm,
            members=tuple(members),
            routes=tuple(routes),
            record_every=record_every,
            warnings=tuple(dict.fromkeys(self.warnings)),
            semantics=self.semantics,
            cut=cut,
        )

    def recording(self, members: list[Member], grid: TimeGrid | None) -> int:
        """Every how many communication points results are recorded; the selection is checked
        to name at least one output each."""
        names = [f"{m.name}.{c.name}" for m in members for c in m.outputs]
        for pattern in self.options.output_variables:
            if members and not any(fnmatch.fnmatchcase(n, pattern) for n in names):
                self.problems.append(
                    f"--output-variables {pattern}: matches no output (outputs: "
                    f"{', '.join(names) or 'none'}); write Component.output names or globs"
                )
        for name in self.options.record:
            if self.scenario.component(name) is None:
                self.problems.append(
                    f"--record {name}: no component '{name}' in the scenario (components: "
                    f"{', '.join(c.name for c in self.scenario.components)})"
                )
        interval = self.options.output_interval
        if interval is None or grid is None:
            return 1
        ratio = interval / grid.step
        every = round(ratio) if math.isfinite(ratio) else 0
        if every < 1 or abs(ratio - every) > 1e-9 * max(1.0, ratio):
            self.problems.append(
                f"--output-interval {interval:g} s is not a whole multiple of the step "
                f"{grid.step:g} s; choose a multiple"
            )
            return 1
        return every

    def guard(self, compute: Callable[[], T]) -> T | None:
        """``compute()``, or None with its ScenarioError collected as a problem."""
        try:
            return compute()
        except ValidationError as exc:
            self.problems.extend(exc.problems)
        except ScenarioError as exc:
            self.problems.append(str(exc))
        return None

    # -- the SSD's own wiring -------------------------------------------------------------

    def structure(self, c: ssp.Connection) -> None:
        """The connection joins connectors that exist and can drive and be driven."""
        what = f"{where(c)}: connection {c.start} -> {c.end}"
        start = self.scenario.connector(c.start_element, c.start_connector)
        end = self.scenario.connector(c.end_element, c.end_connector)
        if start is None or end is None:  # the loader refuses unknown connectors
            return
        if start.kind not in _SOURCES:
            self.problems.append(
                f"{what}: '{c.start}' is {start.kind} and cannot drive a connection; "
                "start from an output or calculatedParameter"
            )
        if end.kind not in _SINKS:
            self.problems.append(
                f"{what}: '{c.end}' is {end.kind} and cannot be driven; "
                "end at an input or parameter"
            )
        if (
            start.type is ValueType.ENUMERATION is end.type
            and start.enumeration != end.enumeration
            and not isinstance(c.transformation, ssp.EnumerationMappingTransformation)
        ):
            self.problems.append(
                f"{what}: enumerations '{start.enumeration}' and '{end.enumeration}' differ; add "
                "an EnumerationMappingTransformation"
            )

    def drivers(self) -> None:
        driving: dict[str, list[ssp.Connection]] = {}
        for c in self.scenario.connections:
            driving.setdefault(c.end, []).append(c)
        for name, those in driving.items():
            if len(those) > 1:
                each = ", ".join(f"line {c.line} from '{c.start}'" for c in those)
                self.problems.append(
                    f"{where(those[0])}: input '{name}' is driven by {len(those)} connections "
                    f"({each}); an input takes exactly one driver: remove all but one"
                )

    # -- each participant against its component --------------------------------------------

    def candidate(self, candidate: Candidate, description: Description) -> None:
        component = candidate.component
        for connector in component.connectors:
            self.connector(candidate, connector, description)
        given = {
            channel_of(component, c.end_connector)
            for c in self.scenario.connections
            if c.end_element == component.name
        } | set(self.semantics.start_inputs(self.scenario, component))
        for channel in description.of(Causality.INPUT):
            if (
                channel.name not in given
                and channel.start is None
                and channel.name not in component.parameters
            ):
                self.problems.append(
                    f"{where(component)}: input '{component.name}.{channel.name}' is neither "
                    f"connected nor has a start value; connect it or bind a value to it"
                )

    def connector(
        self, candidate: Candidate, connector: ssp.Connector, description: Description
    ) -> None:
        component = candidate.component
        what = f"{where(connector, component.file)}: connector '{component.name}.{connector.name}'"
        channel = description.channel(connector.channel)
        if channel is None:
            names = ", ".join(c.name for c in description.channels) or "none"
            named = f" (nameInModel '{connector.name_in_model}')" if connector.name_in_model else ""
            self.problems.append(
                f"{what}{named} does not exist on participant '{description.name}' (its "
                f"channels: {names}); rename the connector or the channel"
            )
            return
        if connector.causality is not None and connector.causality is not channel.causality:
            self.problems.append(
                f"{what} is {connector.kind} in the SSD but the participant declares it "
                f"{channel.causality}; change the connector's kind to {channel.causality}"
            )
        if connector.type is not None and connector.type is not channel.type:
            self.problems.append(
                f"{what} expects {connector.type}, but the participant declares {channel.type}; "
                f"declare the connector <ssc:{channel.type}/>"
            )
        if (
            self.semantics.checks_units
            and connector.unit
            and channel.unit
            and connector.unit != channel.unit
        ):
            declared = self.scenario.units[connector.unit].base_unit
            own = candidate.units.get(channel.unit) or from_symbol(channel.unit)
            if own is None:
                self.warnings.append(
                    f"{what}: the participant's unit '{channel.unit}' is not understood, so it "
                    f"cannot be compared with the SSD's '{connector.unit}'; the SSD's applies"
                )
            elif own != declared:
                self.problems.append(
                    f"{what} has unit '{connector.unit}' in the SSD but the participant declares "
                    f"'{channel.unit}'; declare the participant's unit in the SSD (connections "
                    "convert units)"
                )

    # -- connections against the participants ------------------------------------------------

    def channel(self, element: str, name: str) -> Channel | None:
        """The channel SSD connector ``element.name`` stands for."""
        candidate = self.roster.candidates.get(element)
        description = candidate.description if candidate else None
        if description is None or candidate is None:
            return None
        return description.channel(channel_of(candidate.component, name))

    def route(self, c: ssp.Connection) -> Route | None:
        """The connection's channels, types and unit conversion, or None (problems noted)."""
        source = self.channel(c.start_element, c.start_connector)
        target = self.channel(c.end_element, c.end_connector)
        if source is None or target is None:
            return None  # reported with the connector or the participant
        what = f"{where(c)}: connection {c.start} -> {c.end}"
        start = self.scenario.connector(c.start_element, c.start_connector)
        end = self.scenario.connector(c.end_element, c.end_connector)
        ok = self.types(c, what, source.type, target.type)
        self.sizes(c, what, source, target)
        conversion: Conversion | None = None
        if c.suppress_unit_conversion:
            pass
        elif self.semantics.checks_units:
            conversion = self.units(c, what, start, end, source, target)
        else:
            conversion = self.semantics.conversion(self.scenario, start, end)
        if not ok:
            return None
        return Route(
            connection=c,
            source=source,
            target=target,
            conversion=conversion,
            source_enum=self.scenario.enumerations.get(start.enumeration or "") if start else None,
            target_enum=self.scenario.enumerations.get(end.enumeration or "") if end else None,
        )

    def sizes(self, c: ssp.Connection, what: str, source: Channel, target: Channel) -> None:
        """An output that declares larger values than its input accepts (``max_bytes``)."""
        if not (source.sized and target.sized and source.max_bytes and target.max_bytes):
            return
        if source.max_bytes > target.max_bytes:
            self.problems.append(
                f"{what}: '{c.start}' declares values of up to {source.max_bytes} bytes, but "
                f"'{c.end}' accepts at most {target.max_bytes} bytes (max_bytes); connect an "
                f"input that accepts {source.max_bytes} bytes, or have the output's participant "
                f"send (and declare) at most {target.max_bytes}"
            )

    def message_sizes(self, candidate: Candidate, description: Description) -> None:
        """Warns where a participant's declared maxima together exceed the run's message
        limit: a message over it would fail the run."""
        cap = self.options.max_message_bytes
        for causality, what in ((Causality.OUTPUT, "outputs"), (Causality.INPUT, "inputs")):
            sized = [c for c in description.of(causality) if c.sized]
            total = sum(c.max_bytes for c in sized)
            if sized and all(c.max_bytes for c in sized) and total > cap:
                self.warnings.append(
                    f"{where(candidate.component)}: participant '{candidate.name}' declares "
                    f"{what} of up to {total} bytes together, more than the run's message "
                    f"limit of {cap} bytes ({cap / 2**20:g} MiB): a step carrying more fails "
                    f"the run; raise --max-message-size to {math.ceil(total / 2**20)}"
                )

    def types(self, c: ssp.Connection, what: str, a: ValueType, b: ValueType) -> bool:
        t = c.transformation
        if isinstance(t, ssp.LinearTransformation):
            if b is not ValueType.REAL or a not in (ValueType.REAL, ValueType.INTEGER):
                self.problems.append(
                    f"{what}: a LinearTransformation needs a numeric start and a Real end, but "
                    f"'{c.start}' is {a} and '{c.end}' is {b}"
                )
                return False
            return True
        if t is not None:
            needed = _TRANSFORMED[type(t)]
            if a is not needed or b is not needed:
                self.problems.append(
                    f"{what}: a {type(t).__name__} needs {needed} at both ends, but '{c.start}' "
                    f"is {a} and '{c.end}' is {b}"
                )
                return False
            if isinstance(t, ssp.EnumerationMappingTransformation):
                return self.enumeration_mapping(c, what, t)
            return True
        if a is b or (a, b) in _COMPATIBLE:
            return True
        self.problems.append(
            f"{what}: connector '{c.end}' expects {b}, but '{c.start}' is {a}; connect "
            f"compatible channels or add a transformation"
        )
        return False

    def enumeration_mapping(
        self, c: ssp.Connection, what: str, t: ssp.EnumerationMappingTransformation
    ) -> bool:
        start = self.scenario.connector(c.start_element, c.start_connector)
        end = self.scenario.connector(c.end_element, c.end_connector)
        source = self.scenario.enumerations.get(start.enumeration or "") if start else None
        target = self.scenario.enumerations.get(end.enumeration or "") if end else None
        if source is None or target is None:
            self.problems.append(
                f"{what}: an EnumerationMappingTransformation needs Enumeration connectors with "
                "enumerations defined in the SSD at both ends"
            )
            return False
        unknown = [name for name in t.mapping.values() if name not in target.items]
        if unknown:
            self.problems.append(
                f"{what}: mapping target '{unknown[0]}' is not an item of enumeration "
                f"'{target.name}' (items: {', '.join(target.items)})"
            )
            return False
        return True

    def unit(
        self, element: str, connector: ssp.Connector | None, channel: Channel
    ) -> tuple[str, ssp.BaseUnit | None] | None:
        """(unit name, its BaseUnit or None when not understood) of one end, from the best
        source: the SSD connector's unit, else the participant's declared unit."""
        if connector is not None and connector.unit:
            return connector.unit, self.scenario.units[connector.unit].base_unit
        if channel.unit:
            candidate = self.roster.candidates[element]
            return channel.unit, candidate.units.get(channel.unit) or from_symbol(channel.unit)
        return None

    def units(
        self,
        c: ssp.Connection,
        what: str,
        start: ssp.Connector | None,
        end: ssp.Connector | None,
        source: Channel,
        target: Channel,
    ) -> Affine | None:
        a = self.unit(c.start_element, start, source)
        b = self.unit(c.end_element, end, target)
        if a is None or b is None:
            return None
        (name_a, base_a), (name_b, base_b) = a, b
        if base_a is None or base_b is None:
            if name_a != name_b:
                unknown = name_a if base_a is None else name_b
                self.warnings.append(
                    f"{what}: unit '{unknown}' is not understood, so '{c.start}' [{name_a}] -> "
                    f"'{c.end}' [{name_b}] passes values unconverted; declare it in the SSD's "
                    "<Units> or write a standard symbol (e.g. km/h, degC)"
                )
            return None
        try:
            return affine(base_a, base_b)
        except IncompatibleUnits as exc:
            self.problems.append(
                f"{what}: '{c.start}' is in {name_a} but '{c.end}' is in {name_b}, and {exc}; "
                "connect channels of the same quantity (or mark the connection "
                'suppressUnitConversion="true" if the units are wrong)'
            )
            return None

    # -- values ----------------------------------------------------------------------------

    def overrides(self) -> dict[str, dict[str, Value]]:
        """``--param`` texts as typed values per component."""
        values: dict[str, dict[str, Value]] = {}
        single = len(self.scenario.components) == 1
        for key, text in self.options.parameters.items():
            component, _, name = key.rpartition(".")
            if not component and single:
                component = self.scenario.components[0].name
            candidate = self.roster.candidates.get(component)
            if candidate is None or candidate.description is None:
                if candidate is None:
                    known = ", ".join(self.roster.candidates) or "none"
                    self.problems.append(
                        f"--param {key}: no component '{component}' (components: {known}); "
                        "write COMPONENT.NAME=VALUE"
                    )
                continue
            channel = candidate.description.channel(name)
            if channel is None or channel.causality is Causality.OUTPUT:
                settable = [
                    c.name
                    for c in candidate.description.channels
                    if c.causality is not Causality.OUTPUT
                ]
                close = difflib.get_close_matches(name, settable, n=1)
                self.problems.append(
                    f"--param {key}: no parameter or input '{name}' on component '{component}'"
                    + (f"; did you mean '{component}.{close[0]}'?" if close else "")
                    + f" (its parameters and inputs: {', '.join(settable) or 'none'})"
                )
                continue
            try:
                values.setdefault(component, {})[name] = check_value(
                    channel, parse(channel.type, text)
                )
            except (ValueError, ChannelValueError) as exc:
                self.problems.append(f"--param {key}={text}: not a valid {channel.type} ({exc})")
        return values

    def member(
        self, candidate: Candidate, overrides: Mapping[str, Value], grid: TimeGrid | None
    ) -> Member:
        component, description = candidate.component, candidate.description
        assert description is not None
        parameters: dict[str, Value] = {}
        start_inputs: dict[str, Value] = {}
        bound = {name: (p.value, p.origin) for name, p in component.parameters.items()}
        bound |= {name: (value, "--param") for name, value in overrides.items()}
        problems = []
        for name, (value, origin) in bound.items():
            channel = description.channel(name)
            if channel is None or channel.causality is Causality.OUTPUT:
                problems.append(
                    f"{origin or where(component)}: parameter binding '{component.name}.{name}' "
                    f"names no parameter or input of participant '{description.name}'"
                )
                continue
            try:
                typed = check_value(channel, widen(channel.type, value))
            except ChannelValueError as exc:
                problems.append(f"{origin}: parameter '{component.name}.{name}': {exc}")
                continue
            target = parameters if channel.causality is Causality.PARAMETER else start_inputs
            target[name] = typed
        start_inputs |= self.semantics.start_inputs(self.scenario, component)
        multiple, step = 1, 0.0
        if grid is not None:
            try:
                multiple = multiple_of(component, grid, whole_run=self.semantics.whole_run)
                step = grid.step if component.delta_time is None else component.delta_time
                self.fixed_step(component, description, step)
                if isinstance(candidate.participant, ReplayParticipant):
                    problem = candidate.participant.grid_problem(grid.start, step, grid.stop)
                    if problem is not None:
                        problems.append(
                            f"{where(component)}: component '{component.name}': {problem}"
                        )
            except ScenarioError as exc:
                problems.append(str(exc))
        if problems:
            raise ValidationError(problems)
        return Member(
            name=component.name,
            participant=candidate.participant,
            outputs=description.of(Causality.OUTPUT),
            multiple=multiple,
            step=step,
            deadline=component.settings.call_timeout or self.options.call_timeout,
            parameters=parameters,
            start_inputs=start_inputs,
        )

    def fixed_step(self, component: ssp.Component, description: Description, step: float) -> None:
        fixed = description.capabilities.fixed_step_size
        if not fits_fixed_step(step, fixed):
            raise ScenarioError(
                f"{where(component)}: participant '{component.name}' steps in whole multiples "
                f"of {fixed:g} s, but its communication step is {step:g} s; choose --step "
                f"(or its deltaTime) as a multiple of {fixed:g} s"
            )


def algorithm_of(scenario: ssp.Scenario) -> Algorithm:
    """The scenario's own choice: OpenMCx stepType ``sequential`` is Gauss-Seidel, the
    ``parallel_*`` types are Jacobi; Jacobi when the SSD says nothing."""
    if scenario.step_type == "sequential":
        return Algorithm.GAUSS_SEIDEL
    return Algorithm.JACOBI


def grid_of(scenario: ssp.Scenario, options: RunOptions) -> TimeGrid:
    """The communication points; ScenarioError naming where a bad value came from."""
    source = scenario.source.name

    def pick(
        option: float | None, value: float | None, flag: str, ssd: str
    ) -> tuple[float | None, str]:
        if option is not None:
            return option, flag
        return value, f"{ssd} in {source}"

    start, start_from = pick(options.start_time, scenario.start_time, "--start-time", "startTime")
    stop, stop_from = pick(options.stop_time, scenario.stop_time, "--stop-time", "stopTime")
    step, step_from = pick(options.step_size, scenario.step_size, "--step", "deltaTime")
    if start is None:
        start, start_from = 0.0, "the default"
    if stop is None:
        raise ScenarioError(
            f"{source}: no stop time; give --stop-time T or a DefaultExperiment stopTime in the SSD"
        )
    if step is None:
        step, step_from = DEFAULT_STEP, "the default step (OpenMCx's)"
    for value, origin, what in (
        (start, start_from, "start time"),
        (stop, stop_from, "stop time"),
        (step, step_from, "step size"),
    ):
        if not math.isfinite(value):
            raise ScenarioError(f"{what} {value} ({origin}) is not a finite number; give one")
    if not step > 0:
        raise ScenarioError(f"step size must be positive, got {step:g} s ({step_from})")
    if not stop > start:
        raise ScenarioError(
            f"stop time {stop:g} s ({stop_from}) must be after start time {start:g} s "
            f"({start_from})"
        )
    ratio = (stop - start) / step
    if not ratio <= MAX_STEPS:
        raise ScenarioError(
            f"{start:g} .. {stop:g} s in steps of {step:g} s ({step_from}) is {ratio:.3g} "
            f"communication points, more than {MAX_STEPS:.0e}; check the step's unit"
        )
    steps = round(ratio)
    if not math.isclose(ratio, steps, rel_tol=1e-9, abs_tol=1e-9):
        raise ScenarioError(
            f"stop time {stop:g} s is not start {start:g} s plus a whole number of steps of "
            f"{step:g} s ({ratio:.6g} steps); choose a step that divides the interval"
        )
    return TimeGrid(start=start, step=step, steps=steps)


def multiple_of(component: ssp.Component, grid: TimeGrid, *, whole_run: bool = True) -> int:
    """The component's step multiple m (its deltaTime = m h), checked against the run (where the
    run's semantics let a component step past the stop time: ``whole_run=False``)."""
    delta = component.delta_time
    if delta is None:
        return 1
    what = f"{where(component)}: component '{component.name}' deltaTime"
    if not math.isfinite(delta) or not delta > 0:
        raise ScenarioError(f"{what} {delta} is not a positive finite number of seconds")
    ratio = delta / grid.step
    multiple = round(ratio)
    if multiple < 1 or abs(ratio - multiple) > 1e-9 * max(1.0, ratio):
        raise ScenarioError(
            f"{what} {delta:g} s is not a whole multiple of the step {grid.step:g} s"
        )
    if whole_run and grid.steps % multiple:
        raise ScenarioError(
            f"{what} {delta:g} s does not divide the run {grid.start:g} .. {grid.stop:g} s "
            f"({grid.steps} steps of {grid.step:g} s); choose a stop time the component reaches "
            f"by whole steps of {delta:g} s"
        )
    return multiple


def channel_of(component: ssp.Component, connector: str) -> str:
    """The participant's channel the SSD connector ``connector`` stands for (its OpenMCx
    ``nameInModel``, else its name)."""
    found = component.connector(connector)
    return found.channel if found is not None else connector
