"""Local metric frame: WGS84 latitude/longitude <-> east/north metres around an origin.

An equirectangular projection with the WGS84 meridian and prime-vertical radii of curvature
at the origin's latitude. Over a line spanning +-10 km north-south the east scale drifts by
about ``tan(lat0) * dlat`` (~2e-3 at 50 deg N for 10 km), so lengths are accurate to ~0.1 %
near the line's ends and far better near the origin. The forward and inverse maps are exact
inverses of each other, so data made in this frame round-trip to floating-point precision.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

_A = 6378137.0
"""WGS84 semi-major axis [m]."""
_E2 = 6.69437999014e-3
"""WGS84 first eccentricity squared."""

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LocalFrame:
    """East (x) / north (y) metres around ``(origin_latitude_deg, origin_longitude_deg)``."""

    origin_latitude_deg: float
    origin_longitude_deg: float

    @property
    def north_radius_m(self) -> float:
        """Meridian radius of curvature at the origin [m per radian of latitude]."""
        s = math.sin(math.radians(self.origin_latitude_deg))
        return _A * (1.0 - _E2) / (1.0 - _E2 * s * s) ** 1.5

    @property
    def east_radius_m(self) -> float:
        """Parallel radius at the origin [m per radian of longitude]."""
        phi = math.radians(self.origin_latitude_deg)
        return _A / math.sqrt(1.0 - _E2 * math.sin(phi) ** 2) * math.cos(phi)

    def to_local(
        self, latitude_deg: npt.ArrayLike, longitude_deg: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Geographic degrees -> (x east, y north) metres."""
        lat = np.asarray(latitude_deg, dtype=np.float64)
        lon = np.asarray(longitude_deg, dtype=np.float64)
        x = np.radians(lon - self.origin_longitude_deg) * self.east_radius_m
        y = np.radians(lat - self.origin_latitude_deg) * self.north_radius_m
        return x, y

    def to_geographic(
        self, x_m: npt.ArrayLike, y_m: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """(x east, y north) metres -> (latitude, longitude) degrees."""
        x = np.asarray(x_m, dtype=np.float64)
        y = np.asarray(y_m, dtype=np.float64)
        lat = self.origin_latitude_deg + np.degrees(y / self.north_radius_m)
        lon = self.origin_longitude_deg + np.degrees(x / self.east_radius_m)
        return lat, lon
