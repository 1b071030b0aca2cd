"""Bounds of the durations a run is made of [s]: its lease and the deadlines of its calls.

Each is a finite, positive number of seconds no larger than its ceiling: an infinite lease
would lock a participant for good, an infinite deadline would never free the orchestrator.
Both sides check -- the participant runtime (``coupler.server``: INVALID_ARGUMENT naming the
value and the bound), the orchestrator's command line and the exported FMU's binary -- with
the same bounds (docs/protocol.md, "Rules every participant follows").
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

MAX_LEASE = 86_400.0
"""The longest lease a participant grants [s]: 24 h."""
MAX_TIMEOUT = 86_400.0
"""The longest call deadline or connect timeout [s]: 24 h."""
MIN_LEASE = 1.0
"""The shortest lease the orchestrator asks for [s]: a shorter one (``--lease 1e-300``) runs
out between two calls, and the participant ends the run before its first step (a participant
still grants any positive lease: this is the asking side's sense, not a protocol rule)."""


def problem(value: float, maximum: float) -> str | None:
    """Why ``value`` is not a number of seconds in (0, ``maximum``]; None when it is."""
    if math.isfinite(value) and 0 < value <= maximum:
        return None
    bound = f"{maximum:g} ({maximum / 3600:g} h)"
    return f"must be a number of seconds > 0 and <= {bound}, got {value!r}"


def argument(maximum: float, *, zero: bool = False, minimum: float = 0.0) -> Callable[[str], float]:
    """An argparse type: a number of seconds in (0, ``maximum``] (and 0, with ``zero``), at
    least ``minimum`` when given; the error names the bound (argparse adds the option)."""

    def seconds(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
        if zero and value == 0:
            return value
        if why := problem(value, maximum):
            raise argparse.ArgumentTypeError(why)
        if value < minimum:
            raise argparse.ArgumentTypeError(
                f"must be at least {minimum:g} s, got {value!r}: a participant would end the run "
                "between two calls"
            )
        return value

    return seconds


__all__ = ["MAX_LEASE", "MAX_TIMEOUT", "MIN_LEASE", "argument", "problem"]
