"""OpenRails' world grid: 2048 m tiles laid on MSTS' interrupted Goode homolosine projection.

MSTS and OpenRails place the world on the Goode homolosine projection of a sphere of radius
6 370 997 m, cut into 2048 m tiles; a position is a tile ``(tile_x, tile_z)`` and metres from
the tile's centre, ``x`` east and ``z`` north (``y`` up). OpenRails converts between the two
with the same projection (``WorldLatLon``); :func:`world_of_geographic` and
:func:`geographic_of_world` are that conversion, written from the projection's equations.

A route's track is laid in a local metric frame (:class:`WorldFrame`): its origin is the
Goode position of one geographic point, its axes metres east and north of it. Lengths are
therefore true; the Goode projection is neither conformal nor equidistant, so OpenRails' own
latitude/longitude of a point far from the origin drifts from the point's true coordinates
(see docs/openrails-route.md for the figures).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from coupler_railway.frame import LocalFrame

TILE_SIZE_M = 2048.0
"""Side of a world tile."""
EARTH_RADIUS_M = 6_370_997.0
"""The sphere MSTS' Goode projection is computed on."""
_PHI_LIMIT = 0.710987989993
"""Latitude (rad) where the projection switches from sinusoidal to Mollweide (40 44' 11.8")."""
_MOLLWEIDE_SHIFT = 0.0528035274542
"""Vertical shift of the Mollweide parts (in earth radii) so they meet the sinusoidal part."""
_MOLLWEIDE_X = 0.900316316158
"""2 sqrt(2) / pi."""
_WORLD_X_OFFSET = 20_015_000.0 - 16_384 * TILE_SIZE_M
"""World x (tile_x * 2048 + x) = Goode x + this: MSTS' raster origin and tile numbering."""
_WORLD_Z_OFFSET = -8_673_000.0 + 16_384 * TILE_SIZE_M


def _central_meridian_deg(latitude_deg: float, longitude_deg: float) -> float:
    """The central meridian of the Goode lobe holding a point."""
    if latitude_deg >= 0.0:
        return -100.0 if longitude_deg <= -40.0 else 30.0
    for bound, meridian in ((-100.0, -160.0), (-20.0, -60.0), (80.0, 20.0)):
        if longitude_deg <= bound:
            return meridian
    return 140.0


def _mollweide_theta(phi: float) -> float:
    """Solve 2 theta + sin 2 theta = pi sin phi (Newton)."""
    target = math.pi * math.sin(phi)
    theta = phi
    for _ in range(60):
        step = (2.0 * theta + math.sin(2.0 * theta) - target) / (2.0 + 2.0 * math.cos(2.0 * theta))
        theta -= step
        if abs(step) < 1e-15:
            break
    return theta


def goode_forward(latitude_deg: float, longitude_deg: float) -> tuple[float, float]:
    """Goode homolosine (MSTS' lobes, false easting = R * central meridian) in metres."""
    phi = math.radians(latitude_deg)
    meridian = _central_meridian_deg(latitude_deg, longitude_deg)
    lam = math.radians(longitude_deg - meridian)
    r = EARTH_RADIUS_M
    if abs(phi) < _PHI_LIMIT:
        x, y = r * lam * math.cos(phi), r * phi
    else:
        theta = _mollweide_theta(phi)
        x = _MOLLWEIDE_X * r * lam * math.cos(theta)
        y = math.sqrt(2.0) * r * math.sin(theta) - math.copysign(_MOLLWEIDE_SHIFT * r, phi)
    return x + r * math.radians(meridian), y


def goode_inverse(x: float, y: float) -> tuple[float, float]:
    """Latitude and longitude (degrees) of a Goode position; inverse of :func:`goode_forward`."""
    r = EARTH_RADIUS_M
    if y >= 0.0:
        meridian = -100.0 if x <= r * math.radians(-40.0) else 30.0
    else:
        meridian = 140.0
        for bound, lobe in ((-100.0, -160.0), (-20.0, -60.0), (80.0, 20.0)):
            if x <= r * math.radians(bound):
                meridian = lobe
                break
    x -= r * math.radians(meridian)
    if abs(y) < r * _PHI_LIMIT:
        phi = y / r
        lam = x / (r * math.cos(phi))
    else:
        theta = math.asin((y + math.copysign(_MOLLWEIDE_SHIFT * r, y)) / (math.sqrt(2.0) * r))
        lam = x / (_MOLLWEIDE_X * r * math.cos(theta))
        phi = math.asin((2.0 * theta + math.sin(2.0 * theta)) / math.pi)
    return math.degrees(phi), meridian + math.degrees(lam)


@dataclass(frozen=True)
class WorldPoint:
    """A point on OpenRails' world grid: a tile and metres from its centre."""

    tile_x: int
    tile_z: int
    x: float
    """East of the tile's centre [m], in [-1024, 1024]."""
    z: float
    """North of the tile's centre [m]."""

    @property
    def absolute(self) -> tuple[float, float]:
        """``(tile_x * 2048 + x, tile_z * 2048 + z)``: metres on the world plane."""
        return self.tile_x * TILE_SIZE_M + self.x, self.tile_z * TILE_SIZE_M + self.z

    @classmethod
    def at(cls, east: float, north: float) -> WorldPoint:
        """The tile holding the world-plane point ``(east, north)`` and the offset in it."""
        tile_x = math.floor(east / TILE_SIZE_M + 0.5)
        tile_z = math.floor(north / TILE_SIZE_M + 0.5)
        return cls(tile_x, tile_z, east - tile_x * TILE_SIZE_M, north - tile_z * TILE_SIZE_M)


def world_of_geographic(latitude_deg: float, longitude_deg: float) -> WorldPoint:
    """Where OpenRails puts a geographic point (its ``WorldLatLon`` conversion)."""
    x, y = goode_forward(latitude_deg, longitude_deg)
    return WorldPoint.at(x + _WORLD_X_OFFSET, y + _WORLD_Z_OFFSET)


def geographic_of_world(point: WorldPoint) -> tuple[float, float]:
    """Latitude and longitude OpenRails gives a world point (inverse Goode)."""
    east, north = point.absolute
    return goode_inverse(east - _WORLD_X_OFFSET, north - _WORLD_Z_OFFSET)


def float32(value: float) -> float:
    """``value`` as the nearest single-precision float (what OpenRails reads)."""
    return float(np.float32(value))


@dataclass(frozen=True)
class WorldFrame:
    """A route's local metric frame placed on the world grid.

    ``origin`` is the Goode position of the frame's geographic origin, its offset rounded to
    single precision (the route file's ``RouteStart``); local ``(east, north)`` metres are added
    to it on the world plane.
    """

    local: LocalFrame
    origin: WorldPoint

    @classmethod
    def around(cls, local: LocalFrame) -> WorldFrame:
        point = world_of_geographic(local.origin_latitude_deg, local.origin_longitude_deg)
        return cls(
            local, WorldPoint(point.tile_x, point.tile_z, float32(point.x), float32(point.z))
        )

    def world(self, east: float, north: float) -> WorldPoint:
        """The world point ``east``/``north`` metres from the origin."""
        x0, z0 = self.origin.absolute
        return WorldPoint.at(x0 + east, z0 + north)

    def local_of(self, point: WorldPoint) -> tuple[float, float]:
        """``(east, north)`` of a world point in this frame."""
        x0, z0 = self.origin.absolute
        x, z = point.absolute
        return x - x0, z - z0


def world_file_name(tile_x: int, tile_z: int) -> str:
    """``w-005608+014879.w``: the world file of a tile (sign and six digits each)."""
    return f"w{tile_x:+07d}{tile_z:+07d}.w"


def terrain_tile_name(tile_x: int, tile_z: int) -> str:
    """MSTS' name of a 2048 m terrain tile (without extension): a quadtree path in hex.

    Fifteen halvings of the 32768-tile square, two bits each (north? 0 : 2) + (east == north ?
    1 : 0), packed two levels per hex digit; the odd last level fills the high half of a digit.
    """
    left, bottom, half = -16384, -16384, 16384
    digits = []
    partial = 0
    for level in range(15):
        east = tile_x >= left + half
        north = tile_z >= bottom + half
        partial = (partial << 2) + (0 if north else 2) + (0 if east != north else 1)
        if level % 2 == 1:
            digits.append(f"{partial:X}")
            partial = 0
        if east:
            left += half
        if north:
            bottom += half
        half //= 2
    digits.append(f"{partial << 2:X}")
    return "-" + "".join(digits)
