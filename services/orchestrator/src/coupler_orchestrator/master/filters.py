"""OpenMCx's connection filters: what the target of a connection reads at a given time, from
the points its source wrote (its ``core/connections/filters`` and ``core/Interpolation.c``, the
same arithmetic).

A filter is written after each step of its source (``write(time, value)``: the source's time
and new output), committed at each synchronization point the source enters (``commit(time)``)
and read by its target at the target's read time (``read(time)``). ``begin()`` opens a
synchronization step (OpenMCx's coupling step mode): only then do extrapolation filters take
new values.

- ``Extrapolation(order)``: keeps the last ``order + 1`` committed points; a read at the time of
  one of them gives its value, any other the polynomial through them (order 0: the last value,
  order 1: the line through the last two). Without an inter/extrapolation annotation every
  connection is ``Extrapolation(0)``; so is every non-Real one.
- ``Interpolation(order)``: collects every point written since the last commit; a commit after
  the points read so far swaps the collected points in (keeping the last as the start of the
  next). A read interpolates them: order 0 "step right" (the value at the right end of the
  interval), order 1 linear; outside, the end value (order 0) or the line through the two
  outer points (order 1).
- ``InterExtrapolation(extrapolation, interpolation)``: interpolates when the read time lies
  within the interpolation points (to within ``eps``), else extrapolates (or, where neither
  applies, extrapolates from the interpolation points).
"""

from __future__ import annotations

from coupler.channels import Value

CAPACITY = 1000
"""Points an interpolation collects per synchronization step (OpenMCx's buffer)."""


def _linear(xs: list[float], ys: list[float], x: float) -> float:
    """OpenMCx's ``_mcx_interp_interp_linear``: bisection down to two points, then the line."""
    n = len(xs)
    if n == 1:
        return ys[0]
    if n == 2:
        return ys[0] + (x - xs[0]) * (ys[1] - ys[0]) / (xs[1] - xs[0])
    m = n // 2
    if xs[m] == x:
        return ys[m]
    if xs[m] > x:
        return _linear(xs[: m + 1], ys[: m + 1], x)
    return _linear(xs[n - m - 1 :], ys[n - m - 1 :], x)


def _step_right(xs: list[float], ys: list[float], x: float) -> float:
    """OpenMCx's ``_mcx_interp_interp_step_right``."""
    n = len(xs)
    if n == 1:
        return ys[0]
    if n == 2:
        return ys[0] if x <= xs[0] else ys[1]
    m = n // 2
    if xs[m] == x:
        return ys[m]
    if xs[m] > x:
        return _step_right(xs[: m + 1], ys[: m + 1], x)
    return _step_right(xs[n - m - 1 :], ys[n - m - 1 :], x)


class Comparison:
    """OpenMCx's ``double_cmp``: equal within an absolute ``eps``, or relative to the larger."""

    def __init__(self, eps: float) -> None:
        self.eps = eps

    def equal(self, a: float, b: float) -> bool:
        diff = abs(a - b)
        return diff < self.eps or diff < max(abs(a), abs(b)) * self.eps

    def less(self, a: float, b: float) -> bool:
        return not self.equal(a, b) and a < b

    def greater(self, a: float, b: float) -> bool:
        return not self.equal(a, b) and a > b


class Extrapolation:
    """OpenMCx's ExtFilter (and, at order 0, its DiscreteFilter for non-Real values)."""

    def __init__(self, order: int) -> None:
        self.order = order
        self.xs: list[float] = []
        self.ys: list[Value] = []
        self.open = True
        self._pending: tuple[float, Value] = (0.0, 0.0)
        self._appended = 0

    def begin(self) -> None:
        self.open = True

    def write(self, time: float, value: Value) -> None:
        if self.open:
            self._pending = (time, value)

    def commit(self, time: float) -> None:
        x, y = self._pending
        if self.xs and self.xs[-1] == x:
            self.ys[-1] = y
        elif self._appended < self.order + 1:
            self.xs.append(x)
            self.ys.append(y)
            self._appended += 1
        else:
            del self.xs[0], self.ys[0]
            self.xs.append(x)
            self.ys.append(y)
        self.open = False

    def read(self, time: float) -> Value:
        xs, ys = self.xs, self.ys
        if not xs:
            return 0.0  # nothing committed yet (OpenMCx warns and gives 0)
        for i in range(len(xs) - 1, -1, -1):
            if time == xs[i]:
                return ys[i]
            if time > xs[i]:
                break
        if len(xs) == 1:
            return ys[0]
        return _linear(xs, [float(y) for y in ys], time)


class Interpolation:
    """OpenMCx's IntFilter."""

    def __init__(self, order: int, compare: Comparison) -> None:
        self.order = order
        self.compare = compare
        self.read_xs: list[float] = []
        self.read_ys: list[float] = []
        self._xs: list[float] = []
        self._ys: list[float] = []
        self._last = -1.0

    def begin(self) -> None:
        return None

    def write(self, time: float, value: Value) -> None:
        if time == self._last:
            return
        self._last = time
        if self._xs and self.compare.equal(self._xs[-1], time):
            return
        if len(self._xs) < CAPACITY:
            self._xs.append(time)
            self._ys.append(float(value))
        else:
            self._xs[-1], self._ys[-1] = time, float(value)

    def commit(self, time: float) -> None:
        if not self.read_xs or self.compare.greater(time, self.read_xs[-1]):
            self.read_xs, self.read_ys = self._xs, self._ys
            self._xs = self.read_xs[-1:]
            self._ys = self.read_ys[-1:]

    def read(self, time: float) -> Value:
        xs, ys = self.read_xs, self.read_ys
        if not xs:
            return float("nan")
        if len(xs) == 1:
            return ys[0]
        if time < xs[0] or time > xs[-1]:
            outside = time < xs[0]
            if self.order == 0:
                return ys[0] if outside else ys[-1]
            return _linear(xs[:2], ys[:2], time) if outside else _linear(xs[-2:], ys[-2:], time)
        if self.order == 1:
            return _linear(xs, ys, time)
        return _step_right(xs, ys, time)


class InterExtrapolation:
    """OpenMCx's IntExtFilter."""

    def __init__(self, extrapolation: int, interpolation: int, compare: Comparison) -> None:
        self.extrapolation = Extrapolation(extrapolation)
        self.interpolation = Interpolation(interpolation, compare)
        self.compare = compare

    def begin(self) -> None:
        self.extrapolation.begin()

    def write(self, time: float, value: Value) -> None:
        self.interpolation.write(time, value)
        self.extrapolation.write(time, value)

    def commit(self, time: float) -> None:
        self.interpolation.commit(time)
        self.extrapolation.commit(time)

    def read(self, time: float) -> Value:
        inner, outer, compare = self.interpolation, self.extrapolation, self.compare
        xs = inner.read_xs
        if not xs or compare.less(time, xs[0]) or compare.greater(time, xs[-1]):
            ext = outer.xs
            if not ext or (compare.less(time, ext[-1]) and compare.greater(time, ext[0])):
                return inner.read(time)
            return outer.read(time)
        return inner.read(time)


Filter = Extrapolation | Interpolation | InterExtrapolation
