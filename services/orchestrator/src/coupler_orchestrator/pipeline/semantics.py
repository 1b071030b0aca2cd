"""Coupler's semantics: how the stages read an SSD that no dialect claims (``model.Semantics``).

Units are compared and converted by SSP's unit algebra (``checks``), a member's deltaTime
divides the run, loops are cut nowhere (Gauss-Seidel refuses a loop of connections none of
which is marked decoupled), members step in ``ordering``'s order, and nothing is added to the
plan. A dialect (OpenMCx's, ``pipeline.openmcx``) is another implementation, chosen instead of
this one once, before the checks.
"""

from __future__ import annotations

import graphlib
from collections.abc import Sequence

from coupler.channels import Value
from coupler.errors import ValidationError
from coupler_orchestrator import ssp
from coupler_orchestrator.model import (
    Algorithm,
    Checked,
    Conversion,
    Converter,
    Link,
    OpenMcx,
)
from coupler_orchestrator.pipeline.ordering import execution_order
from coupler_orchestrator.pipeline.participants import where


class CouplerSemantics:
    """Coupler's reading of an SSD (the default)."""

    name = "coupler"
    checks_units = True
    whole_run = True

    def conversion(
        self, scenario: ssp.Scenario, start: ssp.Connector | None, end: ssp.Connector | None
    ) -> Conversion | None:
        return None  # the checks convert (``checks_units``)

    def start_inputs(self, scenario: ssp.Scenario, component: ssp.Component) -> dict[str, Value]:
        return {}

    def entering(self, connector: ssp.Connector) -> Converter | None:
        return None

    def cut_loops(self, scenario: ssp.Scenario, algorithm: Algorithm) -> frozenset[str]:
        if algorithm is Algorithm.GAUSS_SEIDEL:
            problems = gauss_seidel_loops(scenario)
            if problems:
                raise ValidationError(problems)
        return frozenset()

    def order(self, checked: Checked, links: Sequence[Link]) -> tuple[str, ...]:
        return execution_order([m.name for m in checked.members], links, checked.algorithm)

    def additions(self, checked: Checked, links: tuple[Link, ...]) -> OpenMcx | None:
        return None


COUPLER = CouplerSemantics()


def gauss_seidel_loops(scenario: ssp.Scenario) -> list[str]:
    """Every loop of non-decoupled connections, a component feeding itself included: what
    Gauss-Seidel cannot order."""
    problems = []
    predecessors: dict[str, set[str]] = {c.name: set() for c in scenario.components}
    for c in scenario.connections:
        if c.decoupled:
            continue
        if c.start_element == c.end_element:
            problems.append(
                f"{where(c)}: component '{c.start_element}' feeds itself "
                f"({c.start} -> {c.end}), a loop Gauss-Seidel cannot order: mark the "
                f'connection decoupled (annotation org.coupler.connection decoupled="true" '
                f"or OpenMCx decoupling), or run with --algorithm jacobi"
            )
        elif c.end_element in predecessors:
            predecessors[c.end_element].add(c.start_element)
    try:
        graphlib.TopologicalSorter(predecessors).prepare()
    except graphlib.CycleError as exc:
        cycle = list(exc.args[1])[:-1]
        order = [c.name for c in scenario.components]
        first = min(range(len(cycle)), key=lambda i: order.index(cycle[i]))
        loop = [*cycle[first:], *cycle[:first], cycle[first]]
        problems.append(
            f"Gauss-Seidel cannot order the loop {' -> '.join(loop)}: mark one connection of "
            f'it decoupled (annotation org.coupler.connection decoupled="true" or OpenMCx '
            f"decoupling), or run with --algorithm jacobi"
        )
    return problems
