"""The run-time function of a connection: unit conversion, then the transformation."""

from __future__ import annotations

from collections.abc import Callable

from coupler.channels import Value, ValueType
from coupler.errors import ScenarioError

from .model import Connection, Connector, Scenario
from .transformations import transformation_function
from .units import unit_converter


def identity(value: Value) -> Value:
    """The converter of a connection with nothing to convert."""
    return value


def converter(scenario: Scenario, connection: Connection) -> Callable[[Value], Value]:
    """A function turning a value of the start connector into one for the end connector.

    In order: Integer -> Real widening, unit conversion from the start connector's unit to the
    end connector's (``value_in_base = factor * v + offset``, then into the target unit; skipped
    with ``suppressUnitConversion``), then the connection's transformation. Raises
    ScenarioError now, not at run time, when base units disagree. Returns an identity function
    when there is nothing to do.
    """
    c = connection
    what = f"{c.file} line {c.line}: connection {c.start} -> {c.end}"
    start = _connector(scenario, connection.start_element, connection.start_connector, what)
    end = _connector(scenario, connection.end_element, connection.end_connector, what)
    steps: list[Callable[[Value], Value]] = []
    if start.type is ValueType.INTEGER and end.type is ValueType.REAL:
        steps.append(lambda v: float(v))
    if start.unit and end.unit and not connection.suppress_unit_conversion:
        convert = unit_converter(
            scenario.units,
            start.unit,
            end.unit,
            what=f"{what}: '{connection.start}' [{start.unit}] -> '{connection.end}' [{end.unit}]",
        )
        if convert is not None:
            steps.append(lambda v: convert(float(v)))
    if connection.transformation is not None:
        steps.append(
            transformation_function(
                connection.transformation,
                source_enum=scenario.enumerations.get(start.enumeration or ""),
                target_enum=scenario.enumerations.get(end.enumeration or ""),
                what=what,
            )
        )
    if not steps:
        return identity
    if len(steps) == 1:
        return steps[0]

    def chain(value: Value) -> Value:
        for step in steps:
            value = step(value)
        return value

    return chain


def _connector(scenario: Scenario, element: str, name: str, what: str) -> Connector:
    connector = scenario.connector(element, name)
    if connector is None:
        raise ScenarioError(f"{what}: connector '{element}.{name}' does not exist")
    return connector
