"""The run's time grid as a participant sees it: step ends on the exact decimal grid.

The orchestrator's communication points are the doubles nearest to the exact decimals
``t0 + k * h`` the user wrote (0.3, not ``0.1 + 0.1 + 0.1 = 0.30000000000000004``), and each
``DoStep`` carries the step's start and size as such doubles. ``time + step`` in binary
floats drifts off that grid (``0.7 + 0.1 = 0.7999999999999999``, ``1.1 + 0.1 =
1.2000000000000002``: 58 of the first 200 steps of 0.1 s); ``step_end(time, step)`` is the
next point of the grid itself, the time the orchestrator records the step's outputs at.
"""

from __future__ import annotations

from fractions import Fraction

__all__ = ["decimal_of", "step_end"]


def decimal_of(value: float) -> Fraction:
    """The decimal a user wrote for ``value``, exactly: the shortest text that reads back to
    this double (``repr``) -- the text given, for any value of up to 15 significant digits."""
    return Fraction(repr(value))


def step_end(time: float, step: float) -> float:
    """The end of the step from ``time`` by ``step`` on the run's decimal grid: the double
    nearest to ``decimal(time) + decimal(step)`` (``step_end(0.2, 0.1) == 0.3``, where
    ``0.2 + 0.1`` is ``0.30000000000000004``); what ``do_step`` returns its outputs at."""
    return float(decimal_of(time) + decimal_of(step))
