"""The localisation on the map: a localisation under test's estimated front end with its
confidence interval (min/max safe front end), beside the true front end.

Inputs (all start at 0, false; the view appears once the interval is connected, i.e. from the
first step whose ``max_safe_front`` is not 0): ``estimated_front``, ``min_safe_front``,
``max_safe_front`` (metres along the line), ``linking_error``, and ``true_front`` (the test
bench's truth; 0: not connected). Positions along the line become map points through the
line's track model: the estimate a point, the interval the stretch of track between its ends
(one point every ``spacing_m``, at most ``max_points``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from coupler.channels import Value
from coupler_railway import TrackModel


def _real(value: Value | None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return 0.0
    return float(value) if math.isfinite(value) else 0.0


@dataclass
class EstimateView:
    """The latest estimate, as the map shows it."""

    track: TrackModel | None
    spacing_m: float = 5.0
    max_points: int = 200

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.estimate_m = self.min_m = self.max_m = self.true_m = 0.0
        self.linking_error = False
        self.connected = False

    def update(self, inputs: Mapping[str, Value]) -> None:
        self.estimate_m = _real(inputs.get("estimated_front"))
        self.min_m = _real(inputs.get("min_safe_front"))
        self.max_m = _real(inputs.get("max_safe_front"))
        self.true_m = _real(inputs.get("true_front"))
        self.linking_error = bool(inputs.get("linking_error", False))
        self.connected = self.connected or self.max_m != 0.0

    def _point(self, distance_m: float) -> list[float] | None:
        if self.track is None:
            return None
        p = self.track.position(min(max(distance_m, 0.0), self.track.length))
        return [p.latitude_deg, p.longitude_deg]

    def _stretch(self) -> list[list[float]]:
        if self.track is None or self.max_m < self.min_m:
            return []
        n = min(self.max_points, max(2, math.ceil((self.max_m - self.min_m) / self.spacing_m) + 1))
        step = (self.max_m - self.min_m) / (n - 1)
        return [p for i in range(n) if (p := self._point(self.min_m + i * step)) is not None]

    def to_json(self) -> dict[str, Any] | None:
        if not self.connected:
            return None
        has_truth = self.true_m != 0.0
        return {
            "estimate_m": self.estimate_m,
            "min_m": self.min_m,
            "max_m": self.max_m,
            "true_m": self.true_m if has_truth else None,
            "inside": (self.min_m <= self.true_m <= self.max_m) if has_truth else None,
            "linking_error": self.linking_error,
            "estimate": self._point(self.estimate_m),
            "interval": self._stretch(),
            "truth": self._point(self.true_m) if has_truth else None,
        }
