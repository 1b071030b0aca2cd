"""Track model: one line of chained sections as a cubic B-spline with arc-length parameter.

Geographic points go to a :class:`~coupler_railway.frame.LocalFrame` around the first point,
are interpolated by a cubic B-spline in chord-length parameter ``u`` and re-parameterised by
arc length ``s``: ``s(u)`` is integrated with 5-point Gauss-Legendre quadrature on 16
sub-intervals per data interval, and ``u(s)`` is the monotone cubic Hermite interpolant of
those nodes with the exact derivative ``du/ds = 1/|P'(u)|``. Distances are therefore true
spline arc lengths to well below a millimetre.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.interpolate import BSpline, CubicHermiteSpline, make_interp_spline
from scipy.optimize import minimize_scalar

from coupler_railway.frame import FloatArray, LocalFrame

_SUBDIVISIONS = 16
"""Quadrature sub-intervals per interval between two data points."""
_GAUSS_NODES, _GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(5)
_GRID_STEP_M = 2.0
"""Spacing of the coarse samples used to seed :meth:`TrackModel.nearest`."""
_DUPLICATE_M = 1e-3
"""Consecutive points closer than this are one point."""
_EDGE_M = 1e-6
"""Distances this far outside ``[0, length]`` are clipped instead of rejected."""


@dataclass(frozen=True)
class TrackPoint:
    """A point on the track at ``distance`` metres from its start."""

    distance: float
    latitude_deg: float
    longitude_deg: float
    heading_deg: float
    """Direction of increasing distance, degrees clockwise from north in [0, 360)."""
    x_m: float
    """East of the model's origin (its first point) [m]."""
    y_m: float
    """North of the model's origin [m]."""


@dataclass(frozen=True)
class TrackSection:
    """One railML track as a stretch ``[start_distance, start_distance + length]`` of the line."""

    track_id: str
    name: str
    start_distance: float
    length: float


@dataclass(frozen=True)
class SectionGeometry:
    """Input to :meth:`TrackModel.build`: a section's id, name and ordered geo points."""

    track_id: str
    name: str
    latitudes_deg: tuple[float, ...]
    longitudes_deg: tuple[float, ...]


@dataclass(frozen=True)
class GradientChange:
    """From ``offset_m`` into section ``section_index`` on, the slope is ``slope_permille``."""

    section_index: int
    offset_m: float
    slope_permille: float


@dataclass(frozen=True, eq=False)
class TrackModel:
    """The line as one smooth curve; build it with :meth:`build`."""

    frame: LocalFrame
    sections: tuple[TrackSection, ...]
    length: float
    """Arc length of the whole line [m]."""
    point_distances: FloatArray
    """Distance along the line of every (de-duplicated) input point [m]."""
    _spline: BSpline = field(repr=False)
    _derivative: BSpline = field(repr=False)
    _inverse: CubicHermiteSpline = field(repr=False)
    _grid_s: FloatArray = field(repr=False)
    _grid_xy: FloatArray = field(repr=False)
    _gradient_starts: tuple[float, ...] = field(repr=False)
    _gradient_values: tuple[float, ...] = field(repr=False)

    @classmethod
    def build(
        cls,
        sections: Sequence[SectionGeometry],
        gradient_changes: Sequence[GradientChange] = (),
        *,
        frame: LocalFrame | None = None,
    ) -> TrackModel:
        """Chain ``sections`` end to begin into one line; a shared junction point counts once.

        ``frame``: the local frame to work in (lines of one network share one); by default one
        around the first point. Raises ValueError for fewer than two distinct points in total.
        """
        if not sections:
            raise ValueError("a track model needs at least one section")
        first = sections[0]
        if frame is None:
            frame = LocalFrame(first.latitudes_deg[0], first.longitudes_deg[0])
        xs: list[float] = []
        ys: list[float] = []
        first_index: list[int] = []
        for section in sections:
            x, y = frame.to_local(section.latitudes_deg, section.longitudes_deg)
            start = len(xs)
            for i, (px, py) in enumerate(zip(x.tolist(), y.tolist(), strict=True)):
                if xs and math.hypot(px - xs[-1], py - ys[-1]) < _DUPLICATE_M:
                    if i == 0:
                        start = len(xs) - 1
                    continue
                xs.append(px)
                ys.append(py)
            first_index.append(min(start, len(xs) - 1))
        if len(xs) < 2:
            raise ValueError("a track model needs at least two distinct points")
        xy = np.column_stack([xs, ys])
        u = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        spline = make_interp_spline(u, xy, k=min(3, len(u) - 1))
        derivative = spline.derivative()

        t = np.linspace(0.0, 1.0, _SUBDIVISIONS + 1)[:-1]
        nodes_u = np.append((u[:-1, None] + np.diff(u)[:, None] * t[None, :]).ravel(), u[-1])
        a, b = nodes_u[:-1], nodes_u[1:]
        half = (b - a) / 2.0
        quad_u = ((a + b) / 2.0)[:, None] + half[:, None] * _GAUSS_NODES[None, :]
        quad_speed = np.hypot(*derivative(quad_u.ravel()).T).reshape(quad_u.shape)
        nodes_s = np.concatenate([[0.0], np.cumsum(half * (quad_speed @ _GAUSS_WEIGHTS))])
        node_speed = np.hypot(*derivative(nodes_u).T)
        if np.any(node_speed <= 0.0):
            raise ValueError("degenerate track geometry (zero tangent)")
        inverse = CubicHermiteSpline(nodes_s, nodes_u, 1.0 / node_speed)
        length = float(nodes_s[-1])
        point_distances = nodes_s[::_SUBDIVISIONS].copy()

        starts = [float(point_distances[i]) for i in first_index]
        ends = [*starts[1:], length]
        track_sections = tuple(
            TrackSection(s.track_id, s.name, start, end - start)
            for s, start, end in zip(sections, starts, ends, strict=True)
        )

        grid_s = np.linspace(0.0, length, max(2, math.ceil(length / _GRID_STEP_M) + 1))
        grid_xy = spline(inverse(grid_s))

        changes = sorted(
            (starts[c.section_index] + c.offset_m, c.slope_permille) for c in gradient_changes
        )
        return cls(
            frame=frame,
            sections=track_sections,
            length=length,
            point_distances=point_distances,
            _spline=spline,
            _derivative=derivative,
            _inverse=inverse,
            _grid_s=grid_s,
            _grid_xy=grid_xy,
            _gradient_starts=tuple(float(c[0]) for c in changes),
            _gradient_values=tuple(float(c[1]) for c in changes),
        )

    def _scalar(self, distance: float) -> float:
        """``distance`` clipped to the track; ValueError outside it (the scalar fast path)."""
        d = float(distance)
        if not -_EDGE_M <= d <= self.length + _EDGE_M:  # also catches NaN
            raise ValueError(f"distance {d!r} m is outside the track [0, {self.length!r}] m")
        return min(max(d, 0.0), self.length)

    def _checked(self, distance: npt.ArrayLike) -> FloatArray:
        d = np.asarray(distance, dtype=np.float64)
        if np.any(d < -_EDGE_M) or np.any(d > self.length + _EDGE_M) or np.any(np.isnan(d)):
            bad = d[(d < -_EDGE_M) | (d > self.length + _EDGE_M) | np.isnan(d)].flat[0]
            raise ValueError(
                f"distance {float(bad)!r} m is outside the track [0, {self.length!r}] m"
            )
        return np.clip(d, 0.0, self.length)

    def local_xy(self, distances: npt.ArrayLike) -> FloatArray:
        """Local-frame points ``(n, 2)`` [m] at ``distances``."""
        return np.asarray(self._spline(self._inverse(self._checked(distances))))

    def headings(self, distances: npt.ArrayLike) -> FloatArray:
        """Direction of increasing distance at ``distances``: radians clockwise from north
        (the local frame's +y), unwrapped along the array."""
        d = np.atleast_1d(self._checked(distances))
        dx, dy = np.asarray(self._derivative(self._inverse(d))).T
        return np.asarray(np.unwrap(np.arctan2(dx, dy)))

    def coordinates(self, distances: npt.ArrayLike) -> FloatArray:
        """Geographic points ``(n, 2)`` as (latitude, longitude) degrees at ``distances``."""
        xy = self.local_xy(np.atleast_1d(np.asarray(distances, dtype=np.float64)))
        lat, lon = self.frame.to_geographic(xy[:, 0], xy[:, 1])
        return np.column_stack([lat, lon])

    def position(self, distance: float) -> TrackPoint:
        """The point ``distance`` metres along the track."""
        d = self._scalar(distance)
        u = self._inverse(d)
        x, y = (float(v) for v in self._spline(u))
        dx, dy = (float(v) for v in self._derivative(u))
        lat, lon = self.frame.to_geographic(x, y)
        heading = math.degrees(math.atan2(dx, dy)) % 360.0
        return TrackPoint(d, float(lat), float(lon), heading, x, y)

    def nearest(self, latitude_deg: float, longitude_deg: float) -> tuple[float, float]:
        """``(distance along the track, distance from the track [m])`` of the nearest point."""
        x, y = (float(v) for v in self.frame.to_local(latitude_deg, longitude_deg))
        i = int(np.argmin((self._grid_xy[:, 0] - x) ** 2 + (self._grid_xy[:, 1] - y) ** 2))
        lo = float(self._grid_s[max(i - 1, 0)])
        hi = float(self._grid_s[min(i + 1, len(self._grid_s) - 1)])

        def squared(s: float) -> float:
            px, py = self._spline(self._inverse(s))
            return float((px - x) ** 2 + (py - y) ** 2)

        result = minimize_scalar(
            squared, bounds=(lo, hi), method="bounded", options={"xatol": 1e-7}
        )
        best = min((float(result.x), lo, hi), key=squared)
        return best, math.sqrt(squared(best))

    def project(self, latitude_deg: float, longitude_deg: float) -> float:
        """Distance along the track of the point nearest to the given coordinates [m]."""
        return self.nearest(latitude_deg, longitude_deg)[0]

    def locate(self, distance: float) -> tuple[int, float]:
        """``(section index, offset within that section [m])`` of ``distance``."""
        d = self._scalar(distance)
        starts = [s.start_distance for s in self.sections]
        index = max(bisect.bisect_right(starts, d) - 1, 0)
        return index, d - starts[index]

    @property
    def gradient_steps(self) -> tuple[tuple[float, float], ...]:
        """``(distance, slope)`` of every gradient change in distance order: the gradient is
        ``slope`` per mille from ``distance`` on (0 before the first)."""
        return tuple(zip(self._gradient_starts, self._gradient_values, strict=True))

    def gradient(self, distance: float) -> float:
        """Gradient at ``distance`` in per mille (positive uphill); 0 before any change."""
        index = bisect.bisect_right(self._gradient_starts, self._scalar(distance)) - 1
        return self._gradient_values[index] if index >= 0 else 0.0
