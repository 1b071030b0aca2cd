"""Connection transformations (``ssc:GTransformationChoice``): reading them (``wiring`` applies
them)."""

from __future__ import annotations

from coupler.errors import ScenarioError

from .documents import Element, children, elements, integer, local, number, required, where
from .model import (
    BooleanMappingTransformation,
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
