"""What OpenMCx's semantics add to a plan: the evaluation order with its loops cut, how each
connection is read (inter/extrapolation), what a cut connection carries during initialization,
which members read their inputs at the end of their steps or in sub-steps, and what their
output ports do to their outputs (docs/openmcx.md).

Which filter a connection gets (OpenMCx's ``FilterFactory``): a non-Real one and a Real one
without an inter/extrapolation annotation hold the last committed value (extrapolation of order
0); an annotated Real one is read through interpolation and extrapolation when the task is
sequential, and in the parallel step types through extrapolation alone when both orders are the
same (else through both).
"""

from __future__ import annotations

from coupler.channels import Value, ValueType
from coupler_orchestrator import ssp
from coupler_orchestrator.model import (
    Algorithm,
    Checked,
    Converter,
    Filtering,
    Link,
    OpenMcx,
    Route,
)
from coupler_orchestrator.pipeline.checks import openmcx_edges
from coupler_orchestrator.pipeline.dependencies import evaluation_order
from coupler_orchestrator.ssp.openmcx import port_output

_ZERO: dict[ValueType, Value] = {
    ValueType.REAL: 0.0,
    ValueType.INTEGER: 0,
    ValueType.BOOLEAN: False,
    ValueType.STRING: "",
    ValueType.ENUMERATION: 0,
    ValueType.BINARY: b"",
}


def openmcx_of(checked: Checked, links: tuple[Link, ...]) -> OpenMcx | None:
    """OpenMCx's additions to the plan of ``checked``; None when it has Coupler's semantics."""
    if not checked.openmcx:
        return None
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
        order=evaluation_order(names, openmcx_edges(scenario), checked.cut),
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
