"""Connection transformations (``ssc:GTransformationChoice``): reading and applying them."""

from __future__ import annotations

from collections.abc import Callable

from coupler.channels import Value
from coupler.errors import ScenarioError

from .documents import Element, children, elements, integer, local, number, required, where
from .model import (
    BooleanMappingTransformation,
    Enumeration,
    EnumerationMappingTransformation,
    IntegerMappingTransformation,
    LinearTransformation,
    Transformation,
)

NAMES = (
    "LinearTransformation",
    "BooleanMappingTransformation",
    "IntegerMappingTransformation",
    "EnumerationMappingTransformation",
)


def read_transformation(parent: Element, display: str) -> Transformation | None:
    """The transformation child of a Connection or MappingEntry, or None."""
    found = [e for e in elements(parent) if local(e) in NAMES]
    if not found:
        return None
    element = found[0]
    kind = local(element)
    if kind == "LinearTransformation":
        return LinearTransformation(
            factor=number(element, "factor", display, 1.0) or 0.0,
            offset=number(element, "offset", display, 0.0) or 0.0,
        )
    entries = list(children(element, "MapEntry"))
    if kind == "BooleanMappingTransformation":
        return BooleanMappingTransformation(
            mapping={_bool(e, "source", display): _bool(e, "target", display) for e in entries}
        )
    if kind == "IntegerMappingTransformation":
        return IntegerMappingTransformation(
            mapping={
                integer(e, "source", display, 0) or 0: integer(e, "target", display, 0) or 0
                for e in entries
            }
        )
    return EnumerationMappingTransformation(
        mapping={required(e, "source", display): required(e, "target", display) for e in entries}
    )


def _bool(element: Element, attribute: str, display: str) -> bool:
    text = required(element, attribute, display).strip()
    if text not in ("true", "false", "1", "0"):
        raise ScenarioError(f'{where(display, element)}: {attribute}="{text}" is not a boolean')
    return text in ("true", "1")


def transformation_function(
    transformation: Transformation,
    *,
    source_enum: Enumeration | None = None,
    target_enum: Enumeration | None = None,
    what: str = "",
) -> Callable[[Value], Value]:
    """The run-time function of ``transformation``.

    Enumeration values travel as ``int``: an EnumerationMappingTransformation turns the value
    into its item name in ``source_enum``, maps the name and turns it back into the value of
    ``target_enum``.
    """
    if isinstance(transformation, LinearTransformation):
        factor, offset = transformation.factor, transformation.offset

        def linear(value: Value) -> Value:
            return factor * float(value) + offset

        return linear
    if isinstance(transformation, EnumerationMappingTransformation):
        if source_enum is None or target_enum is None:
            raise ScenarioError(
                f"{what}: an EnumerationMappingTransformation needs Enumeration connectors with "
                "enumerations defined in the SSD at both ends"
            )
        by_value = {v: k for k, v in source_enum.items.items()}
        names = transformation.mapping
        unknown = [t for t in names.values() if t not in target_enum.items]
        if unknown:
            raise ScenarioError(
                f"{what}: mapping target '{unknown[0]}' is not an item of enumeration "
                f"'{target_enum.name}' (items: {', '.join(target_enum.items)})"
            )
        table: dict[int, int] = {}
        for value, name in by_value.items():
            mapped = names.get(name, name)
            if mapped in target_enum.items:
                table[value] = target_enum.items[mapped]

        def enumeration(value: Value) -> Value:
            return table.get(value, value) if isinstance(value, int) else value

        return enumeration
    if isinstance(transformation, BooleanMappingTransformation):
        booleans = dict(transformation.mapping)

        def boolean_map(value: Value) -> Value:
            return booleans.get(bool(value), bool(value))

        return boolean_map
    integers = dict(transformation.mapping)

    def integer_map(value: Value) -> Value:
        return integers.get(value, value) if isinstance(value, int) else value

    return integer_map
