"""What the mock's cameras see: the line in 3-D, and what stands on it.

Built once from the route (the railway package's B-spline ``TrackModel``, or any ``Route``)
and the railML infrastructure: the track centreline sampled every ``SAMPLE_SPACING_M`` along
the line, with the elevation integrated from the gradients, and the balises, signals and
platform edges placed by their distance along the line. Coordinates are the route's local
metric frame: x east, y north, z up [m], z = 0 at the line's start; z is the top of the rails.

The renderer asks for the track's frame at any distance (``at``): centre, forward (along the
track, climbing with the gradient) and right (horizontal, across the track).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from coupler_railway import Infrastructure

from .route import Route

FloatArray = npt.NDArray[np.float64]

SAMPLE_SPACING_M = 0.6
"""Spacing of the centreline samples: one sleeper each."""


@dataclass(frozen=True)
class SceneBalise:
    code: int
    """The balise's numeric id (railML ``code``)."""
    distance_m: float
    """Its centre's distance along the line."""
    name: str = ""
    """railML ``id``."""


@dataclass(frozen=True)
class SceneSignal:
    index: int
    """1-based number of the signal on the line (its object id in depth frames)."""
    distance_m: float
    side: float
    """+1: right of the track seen towards increasing distance, -1: left."""
    name: str = ""
    """railML ``id``."""


@dataclass(frozen=True)
class ScenePlatform:
    index: int
    """1-based number of the platform edge on the line (its object id in depth frames)."""
    start_m: float
    end_m: float
    side: float
    """+1: right of the track seen towards increasing distance, -1: left."""
    height_m: float
    """Height of the platform above the top of the rails."""
    name: str = ""
    """railML ``id``."""


class Scene:
    """The line's centreline samples and the objects along it."""

    def __init__(
        self,
        route: Route,
        *,
        balises: Sequence[SceneBalise] = (),
        signals: Sequence[SceneSignal] = (),
        platforms: Sequence[ScenePlatform] = (),
    ) -> None:
        self.length = float(route.length)
        start = route.position(0.0)
        self.place = (float(start.latitude_deg), float(start.longitude_deg))
        """Latitude and longitude of the line's start [deg]: where the sun is computed for."""
        count = max(2, int(np.ceil(self.length / SAMPLE_SPACING_M)) + 1)
        s = np.linspace(0.0, self.length, count)
        xy = _local_xy(route, s)
        gradient = np.array([route.gradient(float(d)) for d in s]) / 1000.0
        z = np.concatenate([[0.0], np.cumsum((gradient[1:] + gradient[:-1]) / 2 * np.diff(s))])
        tangent = np.gradient(xy, s, axis=0)
        tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
        forward = np.column_stack([tangent, gradient])
        forward /= np.linalg.norm(forward, axis=1, keepdims=True)
        self.s: FloatArray = s
        self.xyz: FloatArray = np.column_stack([xy, z])
        self.forward: FloatArray = forward
        self.right: FloatArray = np.column_stack([tangent[:, 1], -tangent[:, 0], np.zeros(count)])
        starts = np.array([section.start_distance for section in route.sections])
        self.section: npt.NDArray[np.int64] = np.maximum(
            np.searchsorted(starts, s, side="right") - 1, 0
        )
        self.balises = tuple(sorted(balises, key=lambda b: b.distance_m))
        self.signals = tuple(sorted(signals, key=lambda g: g.distance_m))
        self.platforms = tuple(sorted(platforms, key=lambda p: p.start_m))

    @classmethod
    def of_infrastructure(cls, infrastructure: Infrastructure) -> Scene:
        """The scene of a railML file read by ``coupler_railway.load_infrastructure``."""
        return cls(
            infrastructure.model,
            balises=[SceneBalise(b.code, b.distance_m, b.id) for b in infrastructure.balises],
            signals=[
                SceneSignal(i + 1, s.distance_m, 1.0 if s.side == "right" else -1.0, s.id)
                for i, s in enumerate(infrastructure.signals)
            ],
            platforms=[
                ScenePlatform(
                    i + 1,
                    p.start_m,
                    p.end_m,
                    1.0 if p.side == "right" else -1.0,
                    p.height_m,
                    p.id,
                )
                for i, p in enumerate(infrastructure.platform_edges)
            ],
        )

    def at(self, distances: npt.ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Centre (top of rail), forward and right unit vectors at ``distances`` (clipped to
        the line), each ``(n, 3)``."""
        d = np.clip(np.atleast_1d(np.asarray(distances, dtype=np.float64)), 0.0, self.length)
        i = np.clip(np.searchsorted(self.s, d, side="right") - 1, 0, len(self.s) - 2)
        t = ((d - self.s[i]) / (self.s[i + 1] - self.s[i]))[:, None]
        centre = self.xyz[i] * (1.0 - t) + self.xyz[i + 1] * t
        forward = self.forward[i] * (1.0 - t) + self.forward[i + 1] * t
        forward /= np.linalg.norm(forward, axis=1, keepdims=True)
        right = self.right[i] * (1.0 - t) + self.right[i + 1] * t
        right /= np.linalg.norm(right, axis=1, keepdims=True)
        return centre, forward, right

    def section_at(self, distances: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """Index of the route section holding each distance."""
        d = np.clip(np.atleast_1d(np.asarray(distances, dtype=np.float64)), 0.0, self.length)
        i = np.clip(np.searchsorted(self.s, d, side="right") - 1, 0, len(self.s) - 1)
        return self.section[i]


def _local_xy(route: Route, s: FloatArray) -> FloatArray:
    """Centreline points ``(n, 2)`` east/north; vectorised where the route can."""
    local_xy = getattr(route, "local_xy", None)
    if local_xy is not None:
        return np.asarray(local_xy(s), dtype=np.float64)
    points = [route.position(float(d)) for d in s]
    return np.array([(p.x_m, p.y_m) for p in points], dtype=np.float64)
