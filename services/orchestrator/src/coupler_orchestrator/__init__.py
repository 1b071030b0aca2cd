"""Coupler's orchestrator: reads an SSP file, checks every participant against it, drives them
in lockstep and records the results (docs/orchestrator.md). The command line is
``coupler_orchestrator.cli``; the names below are the API for programs that run scenarios
themselves (``__all__``; ``tests/test_exported_members.py`` keeps it), each imported when first
used.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from coupler_orchestrator.model import Algorithm
    from coupler_orchestrator.observer import Column, Observer, RunEnd, RunInfo
    from coupler_orchestrator.options import RunOptions
    from coupler_orchestrator.runner import (
        RunOutcome,
        Validation,
        run_scenario,
        validate_scenario,
    )

_HOMES = {
    "Algorithm": "model",
    "Column": "observer",
    "Observer": "observer",
    "RunEnd": "observer",
    "RunInfo": "observer",
    "RunOptions": "options",
    "RunOutcome": "runner",
    "Validation": "runner",
    "run_scenario": "runner",
    "validate_scenario": "runner",
}
"""Each public name and the module of this package that defines it."""

__all__ = [
    "Algorithm",
    "Column",
    "Observer",
    "RunEnd",
    "RunInfo",
    "RunOptions",
    "RunOutcome",
    "Validation",
    "run_scenario",
    "validate_scenario",
]


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'coupler_orchestrator' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"coupler_orchestrator.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
