"""The B-spline track as OpenRails track sections: straights and circular arcs.

OpenRails lays a track node as a chain of vector sections, each a straight or a circular arc
that starts at a stated point with a stated direction. :func:`fit_sections` cuts a stretch of
a :class:`~coupler_railway.TrackModel` into such sections greedily: every section starts on
the B-spline, at its distance, with its direction; it is an arc whose curvature is the
spline's mean curvature over the section (so it ends with the spline's direction) or, where
that fits as well, a straight; and it is as long as it can be while every point of it stays
within ``tolerance_m`` of the spline point at the same distance. Section lengths are exactly
the spline's arc lengths between cuts, so the stretch's length is kept exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from coupler_railway.frame import FloatArray
from coupler_railway.track import TrackModel

MAX_SECTION_M = 1000.0
"""Longest section written (single-precision positions stay within 0.1 mm over it)."""
_MIN_SECTION_M = 0.05
_SAMPLE_M = 0.5
"""Spacing of the points a candidate section is checked at."""
_STRAIGHT_CURVATURE = 1e-7
"""Below this curvature [1/m] (radius 10 000 km) an arc is written as a straight."""


@dataclass(frozen=True)
class Section:
    """One straight or arc of a fitted stretch, in the line's local frame."""

    start: float
    """Distance along the line where the section starts [m]."""
    length: float
    curvature: float
    """1/radius [1/m]: positive curving right (clockwise seen from above), 0 straight."""
    east: float
    """Start point east of the frame's origin [m]."""
    north: float
    heading: float
    """Direction at the start, radians clockwise from north."""

    def points(self, offsets: FloatArray) -> FloatArray:
        """``(n, 2)`` east/north points ``offsets`` metres into the section."""
        t = np.asarray(offsets, dtype=np.float64)
        k = self.curvature
        if k == 0.0:
            return np.column_stack(
                [self.east + t * math.sin(self.heading), self.north + t * math.cos(self.heading)]
            )
        h = self.heading + k * t
        return np.column_stack(
            [
                self.east + (math.cos(self.heading) - np.cos(h)) / k,
                self.north + (np.sin(h) - math.sin(self.heading)) / k,
            ]
        )


class _Samples:
    """The spline sampled once on a fine grid. Sections end on grid points (or at a stop),
    and candidates are checked at the grid points they cover."""

    def __init__(self, model: TrackModel) -> None:
        self.model = model
        count = max(2, math.ceil(model.length / _SAMPLE_M) + 1)
        self.distances = np.linspace(0.0, model.length, count)
        self.points = model.local_xy(self.distances)
        self.headings = model.headings(self.distances)

    def at(self, distance: float) -> tuple[FloatArray, float]:
        """Point and heading at ``distance`` (exact; grid values on grid points)."""
        i = int(np.searchsorted(self.distances, distance))
        if i < len(self.distances) and abs(self.distances[i] - distance) < 1e-9:
            return self.points[i], float(self.headings[i])
        heading = float(self.model.headings([distance])[0])
        # keep the grid's unwrapping so differences of headings are true turns
        near = float(self.headings[min(i, len(self.headings) - 1)])
        heading += 2.0 * math.pi * round((near - heading) / (2.0 * math.pi))
        return self.model.local_xy([distance])[0], heading

    def candidate(self, start: float, end: float) -> tuple[Section, float]:
        """The better of a straight and the mean-curvature arc over ``[start, end]``, and its
        largest distance from the spline point at the same distance."""
        origin, heading = self.at(start)
        end_point, end_heading = self.at(end)
        length = end - start
        lo, hi = np.searchsorted(self.distances, [start, end], side="right")
        t = np.append(self.distances[lo:hi] - start, length)
        spline = np.vstack([self.points[lo:hi], end_point[None, :]])
        best: tuple[Section, float] | None = None
        for curvature in (0.0, (end_heading - heading) / length):
            if best is not None and abs(curvature) < _STRAIGHT_CURVATURE:
                break
            section = Section(start, length, curvature, float(origin[0]), float(origin[1]), heading)
            error = float(np.max(np.hypot(*(section.points(t) - spline).T)))
            if best is None or error < best[1]:
                best = (section, error)
        assert best is not None
        return best


def fit_sections(
    model: TrackModel,
    start: float,
    end: float,
    *,
    tolerance_m: float,
    cuts: Sequence[float] = (),
    max_length: Sequence[tuple[float, float, float]] = (),
) -> list[Section]:
    """Sections covering ``[start, end]`` of ``model``, each within ``tolerance_m`` of it.

    ``cuts``: distances where a section must end (gradient changes). ``max_length``:
    ``(from, to, metres)`` stretches where no section may be longer than ``metres``.
    """
    if not end > start:
        raise ValueError(f"empty stretch [{start}, {end}]")
    samples = _Samples(model)
    grid = samples.distances
    stops = sorted({c for c in cuts if start < c < end} | {end})
    sections: list[Section] = []
    s = start
    for stop in stops:
        while stop - s > 1e-9:
            cap = min([MAX_SECTION_M] + [m for a, b, m in max_length if a - 1e-9 <= s < b - 1e-9])
            if stop - s <= cap:
                section, error = samples.candidate(s, stop)
                if error <= tolerance_m:
                    sections.append(section)
                    s = stop
                    continue
            # the longest fitting section ending on a grid point before the stop
            first = int(np.searchsorted(grid, s + _MIN_SECTION_M, side="left"))
            last = int(np.searchsorted(grid, min(stop - _MIN_SECTION_M, s + cap), side="right"))
            if last <= first:  # the stop is too near for a grid point in between
                sections.append(samples.candidate(s, stop)[0])
                s = stop
                continue
            lo, hi = first, last  # grid[lo] is assumed to fit, grid[hi - 1] is tried
            best = samples.candidate(s, float(grid[lo]))[0]
            while hi - lo > 1:
                mid = (lo + hi) // 2
                trial, error = samples.candidate(s, float(grid[mid]))
                if error <= tolerance_m:
                    lo, best = mid, trial
                else:
                    hi = mid
            sections.append(best)
            s = best.start + best.length
    return sections


@dataclass(frozen=True)
class FitError:
    """How far fitted sections stray from the B-spline."""

    max_lateral_m: float
    """Largest distance of a section point from the spline curve (nearest point)."""
    max_along_m: float
    """Largest distance between a section point and the spline point at the same distance."""


def fit_error(
    model: TrackModel, sections: Sequence[Section], *, spacing_m: float = 0.5
) -> FitError:
    """Measure ``sections`` against ``model`` at points every ``spacing_m``."""
    worst_lateral = worst_along = 0.0
    for section in sections:
        count = max(4, math.ceil(section.length / spacing_m))
        t = np.linspace(0.0, section.length, count + 1)
        points = section.points(t)
        spline = model.local_xy(np.minimum(section.start + t, model.length))
        along = np.hypot(*(points - spline).T)
        worst_along = max(worst_along, float(np.max(along)))
        # lateral: the offset across the spline's direction at the nearest spline point; the
        # nearest point is within `along` of the same-distance point, so refine around it
        headings = model.headings(np.minimum(section.start + t, model.length))
        normal = np.column_stack([np.cos(headings), -np.sin(headings)])
        across = np.abs(np.sum((points - spline) * normal, axis=1))
        worst_lateral = max(worst_lateral, float(np.max(across)))
    return FitError(worst_lateral, worst_along)
