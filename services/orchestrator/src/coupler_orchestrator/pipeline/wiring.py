"""Stage 4: one converter per connection — widen, convert units, transform — and the links the
master routes values through.

Applied to every value that travels a connection, in this order: Integer -> Real widening (the
only implicit type change), the unit conversion ``checks`` established (SSP BaseUnit algebra, or
the run's semantics'), the connection's transformation, then what the target input does to what
enters it by the run's semantics (an OpenMCx port: scale, offset, min, max). A connection with
nothing to do gets no converter at all. Links join the participants' channels (an SSD
connector's OpenMCx ``nameInModel``).
"""

from __future__ import annotations

from coupler.channels import Value, ValueType
from coupler_orchestrator import ssp
from coupler_orchestrator.model import Checked, Converter, Link, Route


def wire(checked: Checked) -> tuple[Link, ...]:
    """The links of every checked connection, in scenario order."""
    return tuple(
        Link(
            source=r.connection.start_element,
            output=r.source.name,
            target=r.connection.end_element,
            input=r.target.name,
            convert=converter(r, checked),
            decoupled=r.connection.decoupled or r.connection.end in checked.cut,
        )
        for r in checked.routes
    )


def converter(route: Route, checked: Checked | None = None) -> Converter | None:
    """The function a value of ``route.source`` goes through to fit ``route.target``."""
    steps: list[Converter] = []
    if route.source.type is ValueType.INTEGER and route.target.type is ValueType.REAL:
        steps.append(float)
    if route.conversion is not None:
        conversion = route.conversion
        steps.append(lambda value: conversion(float(value)))
    transformation = route.connection.transformation
    if transformation is not None:
        steps.append(transformation_function(transformation, route))
    c = route.connection
    end = checked.scenario.connector(c.end_element, c.end_connector) if checked else None
    entering = checked.semantics.entering(end) if checked and end else None
    if entering is not None:
        steps.append(entering)
    if not steps:
        return None
    if len(steps) == 1:
        return steps[0]

    def chain(value: Value) -> Value:
        for step in steps:
            value = step(value)
        return value

    return chain


def transformation_function(transformation: ssp.Transformation, route: Route) -> Converter:
    """The run-time function of ``transformation`` (its fit was checked in ``checks``).

    Enumeration values travel as ``int``: an EnumerationMappingTransformation turns the value
    into its item name in the source's enumeration, maps the name and turns it back into the
    value of the target's enumeration. Unmapped values pass unchanged.
    """
    if isinstance(transformation, ssp.LinearTransformation):
        factor, offset = transformation.factor, transformation.offset

        def linear(value: Value) -> Value:
            return factor * float(value) + offset

        return linear
    if isinstance(transformation, ssp.BooleanMappingTransformation):
        booleans = dict(transformation.mapping)

        def boolean_map(value: Value) -> Value:
            return booleans.get(bool(value), bool(value))

        return boolean_map
    table: dict[int, int]
    if isinstance(transformation, ssp.EnumerationMappingTransformation):
        source, target = route.source_enum, route.target_enum
        assert source is not None and target is not None  # checked
        table = {}
        for value, name in ((v, k) for k, v in source.items.items()):
            mapped = transformation.mapping.get(name, name)
            if mapped in target.items:
                table[value] = target.items[mapped]
    else:
        table = dict(transformation.mapping)

    def integer_map(value: Value) -> Value:
        return table.get(value, value) if isinstance(value, int) else value

    return integer_map
