"""Observers see every step of a run: the CSV recorder, the progress bar, tests, live views."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from coupler.channels import Value


@dataclass(frozen=True, kw_only=True)
class Column:
    """One recorded output."""

    name: str
    """``Component.connector``."""
    unit: str
    """Unit symbol, empty when none."""
    type: str
    """Value type name (Real, Integer, ...)."""


@dataclass(frozen=True, kw_only=True)
class RunInfo:
    """What observers learn when a run starts."""

    run_id: str
    """The run's id."""
    columns: tuple[Column, ...]
    """Recorded outputs, in row order."""
    start_time: float
    """t_0 [s]."""
    stop_time: float
    """Last communication point [s]."""
    step_size: float
    """Base step h [s]."""
    steps: int
    """Number of base steps planned."""


class Observer:
    """Override what you need; every method is called on the event loop and must not block long."""

    def started(self, info: RunInfo) -> None:
        """The participants are initialized; ``stepped`` follows for t_0."""

    def stepped(self, time: float, row: Sequence[Value]) -> None:
        """Outputs at communication point ``time``, aligned with ``RunInfo.columns``."""

    def finished(self, summary: Mapping[str, Any]) -> None:
        """The run ended (completed, aborted or failed); ``summary`` is what summary.json holds."""
