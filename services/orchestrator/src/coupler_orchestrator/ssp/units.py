"""Units: SSP's ``ssc:Units`` and what unit symbols mean, in one algebra.

Every unit Coupler compares is brought to an SSP ``BaseUnit`` (SI exponents kg m s A K mol cd
rad, plus ``value_in_base = factor * value + offset``): units defined in the SSD (or an .ssv/.ssb
file, or an FMU's modelDescription) by their definition, plain symbols a participant declares
(``km/h``, ``degC``) through the pint unit library. Two units convert when their exponents
agree; ``affine`` gives the conversion.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from coupler.errors import ScenarioError

from .documents import Element, child, children, integer, line_of, number, required, where
from .model import BaseUnit, Unit

_SI = {"[mass]": "kg", "[length]": "m", "[time]": "s", "[current]": "A", "[temperature]": "K"}
_SI.update({"[substance]": "mol", "[luminosity]": "cd"})
#: pint treats angles as dimensionless; SSP counts radians. Units (pint names) that are angles:
_ANGLES = {"radian", "degree", "arcminute", "arcsecond", "turn", "revolution", "gradian"}


def read_units(units: Element | None, display: str) -> dict[str, Unit]:
    """The ``ssc:Unit`` children of a ``Units`` element, by name."""
    result: dict[str, Unit] = {}
    if units is None:
        return result
    for element in children(units, "Unit"):
        name = required(element, "name", display)
        if name in result:
            raise ScenarioError(
                f"{where(display, element)}: unit '{name}' is defined twice (first on line "
                f"{result[name].line}); remove one, or give it another name"
            )
        base = child(element, "BaseUnit")
        if base is None:
            raise ScenarioError(f"{where(display, element)}: unit '{name}' lacks <ssc:BaseUnit>")
        exps = {
            k: integer(base, k, display, 0) or 0
            for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
        }
        factor = number(base, "factor", display, 1.0)
        offset = number(base, "offset", display, 0.0)
        assert factor is not None and offset is not None  # defaults given
        if not math.isfinite(factor) or not math.isfinite(offset) or not factor:
            raise ScenarioError(
                f"{where(display, base)}: unit '{name}' needs a finite, non-zero factor and a "
                "finite offset"
            )
        result[name] = Unit(
            name=name,
            base_unit=BaseUnit(**exps, factor=factor, offset=offset),
            file=display,
            line=line_of(element),
        )
    return result


@dataclass(frozen=True)
class Affine:
    """``target = factor * source + offset``: the conversion between two units."""

    factor: float
    offset: float

    def __call__(self, value: float) -> float:
        return self.factor * value + self.offset


@dataclass(frozen=True)
class OpenMcxUnits:
    """OpenMCx's unit conversion between two SSD units, in its own arithmetic:
    ``((x + source.offset) * source.factor) / target.factor - target.offset``, with no check of
    the dimensions (its ``core/Conversion.c``)."""

    source: BaseUnit
    target: BaseUnit

    def __call__(self, value: float) -> float:
        base = (value + self.source.offset) * self.source.factor
        return base / self.target.factor - self.target.offset


class IncompatibleUnits(ScenarioError):
    """Two units of different dimension."""


class UndefinedUnit(ScenarioError):
    """A unit the SSD's ``<Units>`` do not define, used by ``user`` (``connector 'A.x'``) at
    ``place`` (``file line N``)."""

    def __init__(self, unit: str, place: str, user: str, known: Iterable[str]) -> None:
        self.unit, self.place, self.user, self.known = unit, place, user, sorted(known)
        super().__init__(
            f"{place}: {user} uses unit '{unit}', which is not defined in <Units> (units: "
            f"{', '.join(self.known) or 'none'}); define it"
        )


class UndefinedUnits:
    """One problem per undefined unit, however many connectors and parameters use it (one
    cause, one message): its first use, and where else it is used."""

    def __init__(self, problems: list[str]) -> None:
        self._problems = problems
        self._seen: dict[str, tuple[int, UndefinedUnit, list[str]]] = {}

    def report(self, error: UndefinedUnit) -> None:
        if error.unit not in self._seen:
            self._seen[error.unit] = (len(self._problems), error, [])
            self._problems.append(str(error))
            return
        index, first, others = self._seen[error.unit]
        others.append(f"{error.user} ({error.place})")
        self._problems[index] = f"{first}; it is also used by {', '.join(others)}"


def affine(source: BaseUnit, target: BaseUnit) -> Affine | None:
    """The conversion from ``source`` to ``target``; None when they are the same unit.

    IncompatibleUnits when their dimensions differ (the message names the dimensions; the caller
    adds what it connects).
    """
    if source.exponents != target.exponents:
        raise IncompatibleUnits(
            f"{source.dimension()} and {target.dimension()} are different dimensions"
        )
    if source.factor == target.factor and source.offset == target.offset:
        return None
    # base = fa * v + oa = fb * w + ob  =>  w = (fa / fb) * v + (oa - ob) / fb
    return Affine(source.factor / target.factor, (source.offset - target.offset) / target.factor)


def unit_converter(
    units: Mapping[str, Unit], source: str, target: str, *, place: str, user: str
) -> Callable[[float], float] | None:
    """A function converting a value in SSD unit ``source`` to SSD unit ``target``; None when
    nothing is to do. ``user`` (``parameter 'A.k'``) at ``place`` (``file line N``) names the
    culprit in error messages."""
    if source == target:
        return None
    missing = [u for u in (source, target) if u not in units]
    if missing:
        raise UndefinedUnit(missing[0], place, user, units)
    what = f"{place}: {user}"
    try:
        return affine(units[source].base_unit, units[target].base_unit)
    except IncompatibleUnits as exc:
        raise ScenarioError(
            f"{what}: units '{source}' and '{target}' cannot be converted ({exc}); connect "
            "connectors of the same dimension or fix the units"
        ) from exc


@functools.cache
def _registry() -> Any:
    import pint  # imported on first use: most runs convert no symbol

    return pint.UnitRegistry(autoconvert_offset_to_baseunit=True)


_MODELICA_POWER = re.compile(r"(?<=[A-Za-z])(-?\d+)")


@functools.cache
def from_symbol(symbol: str) -> BaseUnit | None:
    """The BaseUnit of a unit symbol; None when the symbol means nothing to the unit library.

    Plain symbols (``km/h``, ``degC``, ``1/s``, ``rad/s``) and Modelica/FMI unit syntax
    (``m.s-1``, ``kg.m2``, ``m/s2``) are understood.
    """
    found = _from_pint(symbol)
    if found is None and any(c.isdigit() or c == "." for c in symbol):
        found = _from_pint(_MODELICA_POWER.sub(r"**\1", symbol.replace(".", "*")))
    return found


def _from_pint(symbol: str) -> BaseUnit | None:
    import pint

    registry = _registry()
    try:
        unit = registry.Unit(symbol)
        zero = registry.Quantity(0.0, unit).to_base_units()
        one = registry.Quantity(1.0, unit).to_base_units()
    except (pint.errors.PintError, AttributeError, TypeError, ValueError, AssertionError):
        return None
    exponents = {name: 0 for name in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")}
    for dimension, power in one.dimensionality.items():
        name = _SI.get(dimension)
        if name is None or power != int(power):
            return None  # a dimension SSP does not have (e.g. currency) or a fractional power
        exponents[name] = int(power)
    radians = 0
    for name, power in unit._units.items():
        if name in _ANGLES:
            radians += int(power)
    exponents["rad"] = radians
    factor = float(one.magnitude - zero.magnitude)
    offset = float(zero.magnitude)
    if not factor or not math.isfinite(factor) or not math.isfinite(offset):
        return None
    return BaseUnit(**exponents, factor=factor, offset=offset)
