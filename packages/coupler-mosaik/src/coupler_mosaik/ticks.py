"""mosaik's time and Coupler's: tick ``k`` is the communication point ``t0 + k * resolution``.

mosaik counts integer ticks from 0, each ``time_resolution`` seconds long; Coupler's points are
the doubles nearest to the exact decimals ``t0 + k * h`` (docs/orchestrator.md). ``Ticks`` turns
one into the other exactly: a tick's time from the decimals the user wrote (``repr`` of the
doubles, as the orchestrator's grid does), a time's tick only when it is a whole number of ticks
(within ``STEP_TOLERANCE``, as ``fits_fixed_step``), else ``ValueError`` saying so.
"""

from __future__ import annotations

from fractions import Fraction

from coupler.channels import STEP_TOLERANCE


class Ticks:
    """Tick ``k`` <-> ``start + k * resolution`` seconds."""

    def __init__(self, start: float, resolution: float) -> None:
        if not resolution > 0:
            raise ValueError(f"a mosaik time_resolution must be > 0 seconds, got {resolution!r}")
        self.start = start
        self.resolution = resolution
        self._start = Fraction(repr(start))
        self._resolution = Fraction(repr(resolution))

    def time(self, tick: int) -> float:
        """The communication point of ``tick`` [s]: nearest double to the exact decimal."""
        return float(self._start + tick * self._resolution)

    def span(self, ticks: int) -> float:
        """``ticks`` ticks as a step size [s]: nearest double to the exact decimal."""
        return float(ticks * self._resolution)

    def ticks(self, seconds: float, what: str = "step") -> int:
        """``seconds`` as a whole number of ticks; ValueError naming ``what`` when it is not."""
        ratio = seconds / self.resolution
        n = round(ratio)
        if abs(ratio - n) > STEP_TOLERANCE * max(1.0, abs(ratio)):
            raise ValueError(
                f"{what} of {seconds!r} s is not a whole number of mosaik ticks of "
                f"{self.resolution!r} s (time_resolution); make it a multiple of "
                f"{self.resolution!r} s"
            )
        return n

    def tick(self, time: float, what: str = "time") -> int:
        """The tick of the communication point ``time``; ValueError when it falls between."""
        return self.ticks(
            time - self.start, what=f"{what} {time!r} s, from the start {self.start!r} s,"
        )
