"""Where the sun stands: elevation and azimuth for a place, a day of the year and a local time.

The standard formulas of NOAA's solar calculator (its "General Solar Position Calculations"
note: the fractional year, the equation of time and the declination as Fourier series after
Spencer, 1971; the hour angle from the true solar time). They are good to about 0.5 degrees
for any year, which is well under what a camera frame shows; atmospheric refraction is left
out (it lifts the sun by 0.5 degrees at the horizon and less above it).

Daylight (``daylight``) turns the sun's elevation into the light the scene gets, relative to
the mock's clear-noon look: a direct beam dimmed by the air mass it crosses (Kasten and
Young's air mass, a broadband optical depth of 0.3), light from the sky falling with the sine
of the elevation, and after sunset a twilight that loses a factor 10 every 2.5 degrees the sun
sinks (about 400 lux at sunset, 3 lux at the end of civil twilight at -6 degrees, as measured
illuminance goes), down to a night floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

NOON_ELEVATION_DEG = 44.5
"""Elevation of the mock's fixed clear-noon sun (``renderer.SUN``): the light ``daylight``
is relative to."""
OPTICAL_DEPTH = 0.3
"""Broadband optical depth of a clear atmosphere (Rayleigh scattering and aerosols)."""
TWILIGHT_DEG_PER_DECADE = 2.5
"""After sunset the sky's light falls tenfold for each of these degrees of solar depression."""
NIGHT_FLOOR = 1e-6
"""Light of a moonless night relative to noon (about 0.1 lux of sky glow against 1e5 lux)."""


@dataclass(frozen=True)
class SunPosition:
    elevation_deg: float
    """Above the horizon (negative: below)."""
    azimuth_deg: float
    """Clockwise from north: 90 east, 180 south."""

    def direction(self) -> tuple[float, float, float]:
        """Unit vector towards the sun: (east, north, up)."""
        elevation, azimuth = math.radians(self.elevation_deg), math.radians(self.azimuth_deg)
        return (
            math.cos(elevation) * math.sin(azimuth),
            math.cos(elevation) * math.cos(azimuth),
            math.sin(elevation),
        )


def sun_position(
    *,
    latitude_deg: float,
    longitude_deg: float,
    day_of_year: int,
    local_time_s: float,
    utc_offset_h: float,
) -> SunPosition:
    """The sun at ``local_time_s`` (seconds since local midnight, ``utc_offset_h`` ahead of
    UTC) on ``day_of_year`` (1 = 1 January) seen from the place (east longitude positive)."""
    hours = local_time_s / 3600.0
    gamma = 2.0 * math.pi / 365.0 * (day_of_year - 1 + (hours - 12.0) / 24.0)
    equation_of_time_min = 229.18 * (
        0.000075
        + 0.001868 * math.cos(gamma)
        - 0.032077 * math.sin(gamma)
        - 0.014615 * math.cos(2 * gamma)
        - 0.040849 * math.sin(2 * gamma)
    )
    declination = (
        0.006918
        - 0.399912 * math.cos(gamma)
        + 0.070257 * math.sin(gamma)
        - 0.006758 * math.cos(2 * gamma)
        + 0.000907 * math.sin(2 * gamma)
        - 0.002697 * math.cos(3 * gamma)
        + 0.00148 * math.sin(3 * gamma)
    )
    offset_min = equation_of_time_min + 4.0 * longitude_deg - 60.0 * utc_offset_h
    true_solar_min = hours * 60.0 + offset_min
    hour_angle = math.radians(true_solar_min / 4.0 - 180.0)
    latitude = math.radians(latitude_deg)
    cos_zenith = math.sin(latitude) * math.sin(declination) + math.cos(latitude) * math.cos(
        declination
    ) * math.cos(hour_angle)
    zenith = math.acos(max(-1.0, min(1.0, cos_zenith)))
    # azimuth from north, clockwise: from the east and north parts of the direction
    east = -math.cos(declination) * math.sin(hour_angle)
    north = math.cos(latitude) * math.sin(declination) - math.sin(latitude) * math.cos(
        declination
    ) * math.cos(hour_angle)
    azimuth = math.degrees(math.atan2(east, north)) % 360.0
    return SunPosition(elevation_deg=90.0 - math.degrees(zenith), azimuth_deg=azimuth)


def air_mass(elevation_deg: float) -> float:
    """Relative optical air mass (Kasten and Young, 1989); 1 with the sun overhead."""
    h = max(elevation_deg, 0.0)
    return 1.0 / (math.sin(math.radians(h)) + 0.50572 * (h + 6.07995) ** -1.6364)


@dataclass(frozen=True)
class Daylight:
    """Light of the scene relative to the mock's clear noon (whose ground shows its colours)."""

    direct: float
    """The sun's beam on a surface facing it (0 below the horizon)."""
    ambient: float
    """Light from the whole sky on any surface."""


AMBIENT_NOON = 0.62
DIRECT_NOON = 0.38
"""The mock's fixed light: a surface's colour times 0.62 + 0.38 * cos(angle to the sun)."""


def daylight(elevation_deg: float) -> Daylight:
    """The sun's and the sky's light for a sun at ``elevation_deg`` (see the module)."""
    noon = math.sin(math.radians(NOON_ELEVATION_DEG)) + 0.01
    if elevation_deg >= 0.0:
        sky = (math.sin(math.radians(elevation_deg)) + 0.01) / noon
        beam = math.exp(-OPTICAL_DEPTH * (air_mass(elevation_deg) - air_mass(NOON_ELEVATION_DEG)))
    else:
        sky = 0.01 / noon * 10.0 ** (elevation_deg / TWILIGHT_DEG_PER_DECADE)
        beam = 0.0
    return Daylight(direct=DIRECT_NOON * beam, ambient=max(AMBIENT_NOON * sky, NIGHT_FLOOR))
