"""Structural checks of a scenario's connections.

Type compatibility: equal types connect; Integer drives Real (widened by the converter); every
other pair is refused (Real -> Integer would truncate, String/Binary/Boolean carry no number).
Enumerations connect to Enumerations (of different enumerations only with an
EnumerationMappingTransformation). Connectors without a declared type are checked later,
against the participant's Describe.
"""

from __future__ import annotations

from collections import Counter

from coupler.channels import ValueType

from .model import Connection, EnumerationMappingTransformation, LinearTransformation, Scenario

_SOURCES = ("output", "calculatedParameter", "inout")
_SINKS = ("input", "parameter", "inout")


def check_connections(scenario: Scenario) -> list[str]:
    """Every structural problem of the connections, each a sentence naming culprit and fix."""
    problems: list[str] = []
    driven: Counter[str] = Counter()
    for c in scenario.connections:
        what = f"{c.file} line {c.line}: connection {c.start} -> {c.end}"
        start = scenario.connector(c.start_element, c.start_connector)
        end = scenario.connector(c.end_element, c.end_connector)
        missing = [n for n, x in ((c.start, start), (c.end, end)) if x is None]
        if start is None or end is None:
            problems.append(f"{what}: connector '{missing[0]}' does not exist; fix the name")
            continue
        driven[c.end] += 1
        if start.kind not in _SOURCES:
            problems.append(
                f"{what}: '{c.start}' is {start.kind} and cannot drive a connection; "
                "start from an output or calculatedParameter"
            )
        if end.kind not in _SINKS:
            problems.append(
                f"{what}: '{c.end}' is {end.kind} and cannot be driven; "
                "end at an input or parameter"
            )
        problems.extend(_types(c, what, start.type, end.type, start.enumeration, end.enumeration))
    for name, count in driven.items():
        if count > 1:
            problems.append(
                f"input '{name}' is driven by {count} connections; "
                "an input takes exactly one driver"
            )
    return problems


def _types(
    c: Connection,
    what: str,
    a: ValueType | None,
    b: ValueType | None,
    enum_a: str | None,
    enum_b: str | None,
) -> list[str]:
    if a is None or b is None:
        return []
    if isinstance(c.transformation, LinearTransformation) and b is not ValueType.REAL:
        return [f"{what}: a LinearTransformation needs a Real end, but '{c.end}' is {b}"]
    if a == b:
        if (
            a is ValueType.ENUMERATION
            and enum_a != enum_b
            and not isinstance(c.transformation, EnumerationMappingTransformation)
        ):
            return [
                f"{what}: enumerations '{enum_a}' and '{enum_b}' differ; add an "
                "EnumerationMappingTransformation"
            ]
        return []
    if a is ValueType.INTEGER and b is ValueType.REAL:
        return []
    return [
        f"{what}: connector '{c.end}' expects {b}, but '{c.start}' is {a}; connect matching types"
    ]
