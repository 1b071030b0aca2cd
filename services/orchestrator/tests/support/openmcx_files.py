"""OpenMCx's result files (``<Component>_res.csv``, ``_in.csv``) read and compared, for the
tests of OpenMCx's dialect: its own examples' and the project's models'."""

from __future__ import annotations

import csv
from pathlib import Path

TOLERANCE = 1e-9
"""Largest difference of a number relative to its column's largest magnitude: OpenMCx prints
14 digits, and gives its FMUs a summed time where Coupler's is exact (docs/openmcx.md)."""


def table(path: Path) -> tuple[list[str], list[str], list[list[str]]]:
    """An OpenMCx result file: (header, units, rows), the ``sep=,`` line checked."""
    with path.open(newline="") as file:
        rows = list(csv.reader(file))
    assert rows[0] == ["sep="] or rows[0] == ["sep=", ""], rows[0]
    return [h.strip() for h in rows[1]], [u.strip() for u in rows[2]], rows[3:]


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def differences(expected: Path, got: Path) -> tuple[list[str], float]:
    """What differs between two OpenMCx result files, and the largest difference of a number
    relative to its column's largest magnitude."""
    head_e, units_e, rows_e = table(expected)
    head_g, units_g, rows_g = table(got)
    problems = []
    if head_e != head_g:
        problems.append(f"{got.name}: header {head_g} != {head_e}")
    if units_e != units_g:
        problems.append(f"{got.name}: units {units_g} != {units_e}")
    if len(rows_e) != len(rows_g):
        problems.append(f"{got.name}: {len(rows_g)} rows, OpenMCx wrote {len(rows_e)}")
    worst = 0.0
    for j, name in enumerate(head_e[: len(head_g)]):
        column = [_number(r[j]) for r in rows_e]
        scale = max((abs(v) for v in column if v is not None), default=0.0) or 1.0
        for i, (want, row) in enumerate(zip(rows_e, rows_g, strict=False)):
            a, b = _number(want[j]), _number(row[j])
            if a is None or b is None:
                if want[j] != row[j]:
                    problems.append(f"{got.name} {name} row {i}: {row[j]!r} != {want[j]!r}")
                continue
            error = abs(a - b) / scale
            worst = max(worst, error)
            if not error <= TOLERANCE:
                problems.append(f"{got.name} {name} at t={want[0]}: {b!r} != OpenMCx's {a!r}")
    return problems, worst
