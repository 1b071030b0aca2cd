"""The OpenMCx dialect as a translation stage: whether a scenario has OpenMCx's semantics is
decided here, once, before the checks (``semantics_of``), and what its annotations mean is
given to the generic stages as a ``Semantics`` (``model.Semantics``) that never makes them name
OpenMCx (docs/openmcx.md):

- units: converted between the units the SSD gives both connectors, in OpenMCx's arithmetic,
  with no dimension check and no comparison with the participant's unit;
- a member's deltaTime may step past the stop time;
- input ports: a default is the start value of an input nothing drives, and a value entering
  a port goes through its scale, offset, min and max;
- loops: cut as OpenMCx cuts them (``dependencies``), members in OpenMCx's evaluation order;
- the plan's additions (``model.OpenMcx``, run by ``master.openmcx``): how each connection is
  read (inter/extrapolation), what a cut connection carries during initialization, which
  members read their inputs at the end of their steps or in sub-steps, and what their output
  ports do to their outputs.

Which filter a connection gets (OpenMCx's ``FilterFactory``): a non-Real one and a Real one
without an inter/extrapolation annotation hold the last committed value (extrapolation of order
0); an annotated Real one is read through interpolation and extrapolation when the task is
sequential, and in the parallel step types through extrapolation alone when both orders are the
same (else through both).
"""

from __future__ import annotations

from collections.abc import Sequence

from coupler.channels import Value, ValueType
from coupler.errors import ValidationError
from coupler_orchestrator import ssp
from coupler_orchestrator.model import (
    Algorithm,
    Checked,
    Conversion,
    Converter,
    Filtering,
    Link,
    OpenMcx,
    Route,
    Semantics,
)
from coupler_orchestrator.options import RunOptions
from coupler_orchestrator.pipeline import dependencies
from coupler_orchestrator.pipeline.semantics import COUPLER
from coupler_orchestrator.ssp.openmcx import port_input, port_output
from coupler_orchestrator.ssp.units import OpenMcxUnits


def semantics_of(scenario: ssp.Scenario, options: RunOptions) -> Semantics:
    """How the run reads ``scenario``: with OpenMCx's semantics when it uses anything only
    OpenMCx defines (``Scenario.openmcx`` says what) or ``--openmcx`` asks for them, else
    Coupler's."""
    if scenario.openmcx or options.openmcx:
        return OPENMCX
    return COUPLER


class OpenMcxSemantics:
    """OpenMCx's reading of an SSD (``model.Semantics``)."""

    name = "openmcx"
    checks_units = False
    whole_run = False

    def conversion(
        self, scenario: ssp.Scenario, start: ssp.Connector | None, end: ssp.Connector | None
    ) -> Conversion | None:
        """OpenMCx's unit conversion: between the units the SSD gives both connectors (its
        ``<Units>`` only, no dimension check); none when either has no unit or both the same."""
        if start is None or end is None or not start.unit or not end.unit:
            return None
        if start.unit == end.unit:
            return None
        return OpenMcxUnits(
            source=scenario.units[start.unit].base_unit, target=scenario.units[end.unit].base_unit
        )

    def start_inputs(self, scenario: ssp.Scenario, component: ssp.Component) -> dict[str, Value]:
        """Port defaults of the inputs nothing drives, through the port's scale, offset, min
        and max: the start values of those inputs."""
        driven = {c.end_connector for c in scenario.connections if c.end_element == component.name}
        return {
            c.channel: port_input(c)(c.port.default)
            for c in component.connectors
            if c.kind == "input" and c.name not in driven and c.port and c.port.default is not None
        }

    def entering(self, connector: ssp.Connector) -> Converter | None:
        """What the input port does to what enters it (scale, offset, min, max)."""
        if connector.port is not None and connector.port.transforms:
            return port_input(connector)
        return None

    def cut_loops(self, scenario: ssp.Scenario, algorithm: Algorithm) -> frozenset[str]:
        """The connections OpenMCx cuts to break algebraic loops (by driven input); a loop
        nothing may be cut in is a problem."""
        names = [c.name for c in scenario.components]
        sequence = {c.name: c.trigger_sequence for c in scenario.components}
        try:
            return dependencies.cut_loops(names, edges(scenario), sequence)
        except dependencies.Uncuttable as exc:
            raise ValidationError(
                [
                    f"the loop {exc} cannot be broken: every connection of it is marked "
                    "<mc:Never/> (or from a component with a lower triggerSequence); let one be "
                    "decoupled (<mc:IfNeeded/>, the default, or <mc:Always/>)"
                ]
            ) from None

    def order(self, checked: Checked, links: Sequence[Link]) -> tuple[str, ...]:
        """OpenMCx's evaluation order, loops cut."""
        names = [m.name for m in checked.members]
        return dependencies.evaluation_order(names, edges(checked.scenario), checked.cut)

    def additions(self, checked: Checked, links: tuple[Link, ...]) -> OpenMcx | None:
        return openmcx_of(checked, links)


OPENMCX = OpenMcxSemantics()


def edges(scenario: ssp.Scenario) -> list[dependencies.Edge]:
    """Every connection as OpenMCx's ordering sees it (``IfNeeded`` unless it says else)."""
    return [
        dependencies.Edge(
            key=c.end,
            source=c.start_element,
            target=c.end_element,
            decouple="always" if c.decoupled else (c.decouple_type or "if_needed"),
            priority=c.decouple_priority or 0,
        )
        for c in scenario.connections
    ]


_ZERO: dict[ValueType, Value] = {
    ValueType.REAL: 0.0,
    ValueType.INTEGER: 0,
    ValueType.BOOLEAN: False,
    ValueType.STRING: "",
    ValueType.ENUMERATION: 0,
    ValueType.BINARY: b"",
}


def openmcx_of(checked: Checked, links: tuple[Link, ...]) -> OpenMcx:
    """OpenMCx's additions to the plan of ``checked``."""
    scenario = checked.scenario
    sequential = checked.algorithm is Algorithm.GAUSS_SEIDEL
    task = scenario.task
    names = [m.name for m in checked.members]
    routes = {(r.connection.end_element, r.target.name): r for r in checked.routes}
    filters = {}
    initial = {}
    for link in links:
        route = routes[(link.target, link.input)]
        filters[(link.target, link.input)] = filtering(route.connection, route, sequential)
        if link.decoupled:
            initial[(link.target, link.input)] = initial_value(scenario, route, link)
    outputs: dict[str, dict[str, Converter]] = {}
    for component in scenario.components:
        for c in component.connectors:
            if c.kind == "output" and c.port is not None and c.port.transforms:
                outputs.setdefault(component.name, {})[c.channel] = port_output(c)
    return OpenMcx(
        sequential=sequential,
        order=dependencies.evaluation_order(names, edges(scenario), checked.cut),
        first_component=task is not None and task.end_type == "first_component",
        eps=(task.relative_eps if task else 1e-10) * checked.grid.step,
        filters=filters,
        initial=initial,
        input_at_end=frozenset(c.name for c in scenario.components if c.input_at_end_time),
        own_time=frozenset(c.name for c in scenario.components if c.delta_time is not None),
        sub_steps={
            c.name: c.builtin.sub_steps
            for c in scenario.components
            if isinstance(c.builtin, ssp.Integrator) and c.builtin.sub_steps > 1
        },
        outputs=outputs,
    )


def filtering(connection: ssp.Connection, route: Route, sequential: bool) -> Filtering:
    """How the target reads ``connection`` (the filter OpenMCx's ``FilterFactory`` makes)."""
    settings = connection.inter_extrapolation
    if settings is None or route.source.type is not ValueType.REAL:
        return Filtering()
    same = settings.extrapolation_order == settings.interpolation_order
    if not sequential and same:
        return Filtering(extrapolation=settings.extrapolation_order)
    return Filtering(
        extrapolation=settings.extrapolation_order,
        interpolation=settings.interpolation_order,
    )


def initial_value(scenario: ssp.Scenario, route: Route, link: Link) -> Value:
    """What a cut connection carries during initialization: the input port's ``initial``, else
    the output port's, else 0 (of the source's type), through the connection's conversions."""
    connection = route.connection
    start = scenario.connector(connection.start_element, connection.start_connector)
    end = scenario.connector(connection.end_element, connection.end_connector)
    source_type = route.source.type
    value: Value | None = None
    if end is not None and end.port is not None and end.port.initial is not None:
        value = end.port.initial
        if source_type is ValueType.REAL:
            value = float(value)
    elif start is not None and start.port is not None and start.port.initial is not None:
        value = start.port.initial
    if value is None:
        value = _ZERO.get(source_type, 0.0)
    return link.convert(value) if link.convert else value
