"""SSP units: reading ``ssc:Units`` and converting values between units of one dimension."""

from __future__ import annotations

from collections.abc import Callable, Mapping

from coupler.errors import ScenarioError

from .documents import Element, child, children, integer, line_of, number, required, where
from .model import BaseUnit, Unit


def read_units(units: Element | None, display: str) -> dict[str, Unit]:
    """The ``ssc:Unit`` children of a ``Units`` element, by name."""
    result: dict[str, Unit] = {}
    if units is None:
        return result
    for element in children(units, "Unit"):
        name = required(element, "name", display)
        base = child(element, "BaseUnit")
        if base is None:
            raise ScenarioError(f"{where(display, element)}: unit '{name}' lacks <ssc:BaseUnit>")
        exps = {
            k: integer(base, k, display, 0) or 0
            for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
        }
        result[name] = Unit(
            name=name,
            base_unit=BaseUnit(
                **exps,
                factor=number(base, "factor", display, 1.0) or 0.0,
                offset=number(base, "offset", display, 0.0) or 0.0,
            ),
            file=display,
            line=line_of(element),
        )
    return result


def unit_converter(
    units: Mapping[str, Unit], source: str, target: str, *, what: str
) -> Callable[[float], float] | None:
    """A function converting a value in ``source`` to ``target``; None when nothing to do.

    ``what`` names the culprit in error messages (e.g. the two connectors).
    """
    if source == target:
        return None
    missing = [u for u in (source, target) if u not in units]
    if missing:
        raise ScenarioError(
            f"{what}: unit '{missing[0]}' is not defined in the SSD's <Units>; "
            f"define it (known units: {', '.join(sorted(units)) or 'none'})"
        )
    a, b = units[source].base_unit, units[target].base_unit
    if a.exponents != b.exponents:
        raise ScenarioError(
            f"{what}: units '{source}' ({a.dimension()}) and '{target}' ({b.dimension()}) have "
            "different base units and cannot be converted; connect connectors of the same "
            "dimension or fix the units"
        )
    if a.factor == b.factor and a.offset == b.offset:
        return None
    fa, oa, fb, ob = a.factor, a.offset, b.factor, b.offset

    def convert(value: float) -> float:
        return (fa * value + oa - ob) / fb

    return convert
