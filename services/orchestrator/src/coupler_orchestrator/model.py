"""The run's data types, one name per concept, in the order the pipeline makes them.

Nothing here does anything: every stage reads these and makes the next (docs/orchestrator.md,
"How a run flows"). Imports nothing heavy, so that the command line can name the choices.
"""

from __future__ import annotations

from enum import StrEnum


class Algorithm(StrEnum):
    """Master algorithms."""

    JACOBI = "jacobi"
    GAUSS_SEIDEL = "gauss-seidel"
