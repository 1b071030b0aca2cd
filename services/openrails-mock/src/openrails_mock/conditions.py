"""The world a camera sees: light, weather, the balises' surface and the camera itself.

One frozen ``Conditions`` holds every parameter, each with its physical meaning and unit. The
defaults are the mock's clear-noon look (the one before conditions existed: a fixed sun, a
9 km haze, clean balises, an ideal camera), so a run that sets nothing renders as before.
Everything random is drawn from ``seed``: the same conditions, place and time give the same
bytes.

OpenRails takes its world at start, on its command line: the time of day ``HH:MM``, the
season (``Season`` 0-3) and the weather (``Weather`` 0-2), as its simulation client's
``Environment`` holds them. The mock takes the same (``openrails_mock.__main__``), the same
as options, from ``POST /API/RESET {"Environment": {...}}`` per run (a mock extension, what
the bridge sends from its SSD parameters), and as ``environment_file`` (JSON). Naming the
season or the weather brings its defaults (``resolved``): rain 4 mm/h in rain, snowfall
1 mm/h in snow, snow over 60 % of each balise's top in winter snow, leaves in autumn; a value
given explicitly wins.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

from coupler.errors import ScenarioError
from coupler_railway.openrails.config import read_json

Light = Literal["fixed", "sun"]
Season = Literal["spring", "summer", "autumn", "winter"]
Weather = Literal["clear", "snow", "rain"]
SEASONS: tuple[Season, ...] = get_args(Season)
"""OpenRails' ``Season`` in its order: SPRING = 0 ... WINTER = 3."""
WEATHERS: tuple[Weather, ...] = get_args(Weather)
"""OpenRails' ``Weather`` in its order: CLEAR = 0, SNOW = 1, RAIN = 2."""
SEASON_DAY = {"spring": 105, "summer": 196, "autumn": 288, "winter": 15}
"""The day of the year each season's sun stands for: the middle of the meteorological
season (15 April, 15 July, 15 October, 15 January)."""

KOSCHMIEDER = math.log(20.0)
"""-ln(0.05): meteorological visibility is where a black object's contrast falls to 5 %, so
the extinction coefficient is ln(20) / visibility (Koschmieder)."""
DEFAULT_VISIBILITY_M = 3000.0 * KOSCHMIEDER
"""The mock's clear haze: an extinction of 1 / 3000 m (8987 m visibility)."""
RAIN_MM_PER_H = 4.0
SNOWFALL_MM_PER_H = 1.0
WINTER_SNOW_COVER = 0.6
AUTUMN_LEAVES_PER_M2 = 0.15


@dataclass(frozen=True, kw_only=True)
class Conditions:
    """Every condition of the rendered world (see docs/railway-perception.md, "Conditions")."""

    # --- light
    light: Light = "fixed"
    """``fixed``: the mock's clear-noon light whatever the clock says (a sun 44.5 degrees high
    in the south-west, no cast shadows); ``sun``: the sun of the time of day, the season and
    the line's place (``sun.py``), shading and cast shadows, dusk and night."""
    season: Season = "summer"
    """OpenRails' season: the date of the sun, leaves in autumn, snow in winter."""
    day_of_year: int | None = None
    """The date of the sun (1 = 1 January); unset: the season's middle (``SEASON_DAY``)."""
    utc_offset_h: float = 1.0
    """The clock's offset from UTC [h] (1: central European time)."""
    headlights: bool = True
    """The train's headlights (light ``sun`` only): 300 kcd along the track, 1 m above the
    rails at the train's front, dipped 0.5 degrees, falling off as 1 / (1 + (angle / 8
    degrees)^2)^2 off its axis."""
    trees_per_km: float = 0.0
    """Trees beside the line [per km of line, both sides], placed from ``seed``; they cast
    shadows."""
    platform_roofs: bool = False
    """A roof over every platform, 3.2 m above it (casts shadows onto the track)."""
    # --- weather
    weather: Weather = "clear"
    """OpenRails' weather; rain and snow bring their precipitation (``resolved``)."""
    visibility_m: float = DEFAULT_VISIBILITY_M
    """Meteorological visibility of the air (fog, haze) [m]: contrast falls as
    exp(-ln(20) d / visibility) (Koschmieder); 50 is dense fog."""
    rain_mm_per_h: float | None = None
    """Rain rate [mm/h]: extinction (Carbonneau: 1.076 R^0.67 dB/km), wet ballast and ground
    (darker by up to 35 %), streaks."""
    snowfall_mm_per_h: float | None = None
    """Snowfall rate, water equivalent [mm/h]: extinction (dry snow: 5.42 S^1.38 dB/km) and
    falling flakes."""
    snow_cover: float | None = None
    """Fraction of each balise's surface hidden under snow (0..1; which part, seeded per
    balise and face: drifts of 4 cm cells); the ground is snow-covered as well when it is
    above 0."""
    # --- the balises' surface
    dirt: float = 0.0
    """Mean dirt and wear of the balises (0..1): the fraction of colour and saturation lost,
    drawn per balise between 0.5 and 1.5 times this."""
    leaves_per_m2: float | None = None
    """Autumn leaves and other yellow things on and beside the ballast [clumps per m2];
    unset: 0.15 in autumn, none otherwise."""
    # --- the camera
    exposure_ms: float = 1.0
    """Exposure time [ms]: 1 ms at gain 1 renders the scene's colours as they are; the motion
    blur is as long as the way the scene moves in it."""
    gain: float = 1.0
    """Gain of the sensor (1: a surface lit as at noon shows its colour)."""
    auto_exposure: bool | None = None
    """Exposure and gain chosen per frame so that the frame's lower two thirds average 40 %
    of full scale: exposure first (up to ``max_exposure_ms``), then gain (up to
    ``max_gain``). Unset: on with light ``sun`` (as a camera outdoors), off with ``fixed``."""
    max_exposure_ms: float = 20.0
    max_gain: float = 32.0
    noise: bool = False
    """Sensor noise: shot noise of the photo-electrons and read noise."""
    full_well_e: float = 10000.0
    """Photo-electrons that fill a pixel at gain 1 [e-]: shot noise is their square root."""
    read_noise_e: float = 5.0
    """Read noise [e- rms]."""
    motion_blur: bool = False
    """Blur each pixel along the image motion of the train's speed during ``exposure_ms``."""
    jpeg_quality: int = 0
    """Lossy compression: the frame is JPEG-encoded at this quality (1..95) and decoded
    again; 0: none."""
    seed: int = 0
    """Seeds everything random: trees, leaves, dirt, snow on balises, precipitation, noise."""

    @property
    def date(self) -> int:
        return self.day_of_year if self.day_of_year is not None else SEASON_DAY[self.season]

    @property
    def automatic(self) -> bool:
        """Whether exposure and gain follow the light (``auto_exposure``)."""
        return self.auto_exposure if self.auto_exposure is not None else self.light == "sun"

    @property
    def rain(self) -> float:
        if self.rain_mm_per_h is not None:
            return self.rain_mm_per_h
        return RAIN_MM_PER_H if self.weather == "rain" else 0.0

    @property
    def snowfall(self) -> float:
        if self.snowfall_mm_per_h is not None:
            return self.snowfall_mm_per_h
        return SNOWFALL_MM_PER_H if self.weather == "snow" else 0.0

    @property
    def snow(self) -> float:
        if self.snow_cover is not None:
            return self.snow_cover
        return WINTER_SNOW_COVER if self.weather == "snow" and self.season == "winter" else 0.0

    @property
    def leaves(self) -> float:
        if self.leaves_per_m2 is not None:
            return self.leaves_per_m2
        return AUTUMN_LEAVES_PER_M2 if self.season == "autumn" else 0.0

    @property
    def extinction_per_m(self) -> float:
        """Extinction coefficient of the air [1/m]: fog and haze, rain and snow."""
        db_per_km = 0.0
        if self.rain > 0.0:
            db_per_km += 1.076 * self.rain**0.67
        if self.snowfall > 0.0:
            db_per_km += 5.42 * self.snowfall**1.38
        return KOSCHMIEDER / self.visibility_m + db_per_km / (10.0 * math.log10(math.e)) / 1000.0

    @property
    def changes_with_time(self) -> bool:
        """Whether a frame depends on the time as well as the place (a standing train's
        frames change: the sun moves, rain falls, noise is drawn anew)."""
        return self.light == "sun" or self.rain > 0 or self.snowfall > 0 or self.noise

    def updated(self, changes: Mapping[str, Any], *, source: str) -> Conditions:
        """These conditions with ``changes`` (names as the fields, OpenRails' season and
        weather numbers taken too), each checked; ScenarioError naming ``source``, the key and
        the fix."""
        fields = {f.name: f for f in dataclasses.fields(self)}
        values: dict[str, Any] = {}
        for key, value in changes.items():
            if key not in fields:
                raise ScenarioError(
                    f"{source}: unknown condition {key!r}; the conditions are {', '.join(fields)}"
                )
            values[key] = _checked(key, value, source)
        return dataclasses.replace(self, **values)


def read_environment(path: Path) -> dict[str, Any]:
    """An environment file: a JSON object of conditions (checked when applied)."""
    data = read_json(path, what="environment file", setting="--environment")
    if not isinstance(data, dict):
        raise ScenarioError(
            f'{path}: an environment file is a JSON object of conditions, e.g. {{"weather": '
            f'"snow", "visibility_m": 200}}, not {type(data).__name__}'
        )
    return data


def clock_of(value: object, source: str) -> float:
    """A time of day: ``HH:MM`` (OpenRails' command line), ``HH:MM:SS`` or seconds since
    midnight."""
    if isinstance(value, str) and ":" in value:
        parts = value.strip().split(":")
        if 2 <= len(parts) <= 3 and all(p.isdigit() for p in parts):
            h, m, sec = (int(p) for p in [*parts, "0"][:3])
            if h < 24 and m < 60 and sec < 60:
                return float(h * 3600 + m * 60 + sec)
        raise ScenarioError(f"{source}: a time of day is HH:MM (00:00 to 23:59), got {value!r}")
    seconds = _number("time", value, source)
    if not 0.0 <= seconds < 86400.0:
        raise ScenarioError(
            f"{source}: a time of day is 0 to 86400 seconds since midnight, got {value!r}"
        )
    return seconds


def season_of(value: object, source: str = "season") -> Season:
    """A season by name or OpenRails' number (0 spring ... 3 winter)."""
    return _choice(value, SEASONS, source, "season")  # type: ignore[return-value]


def weather_of(value: object, source: str = "weather") -> Weather:
    """A weather by name or OpenRails' number (0 clear, 1 snow, 2 rain)."""
    return _choice(value, WEATHERS, source, "weather")  # type: ignore[return-value]


def _choice(value: object, names: tuple[str, ...], source: str, key: str) -> str:
    if isinstance(value, str) and value.strip().lower() in names:
        return value.strip().lower()
    number: object = value
    if isinstance(value, str) and value.strip().isdigit():
        number = int(value.strip())
    if (
        isinstance(number, int | float)
        and not isinstance(number, bool)
        and number in range(len(names))
    ):
        return names[int(number)]
    choices = ", ".join(f"{n} ({i})" for i, n in enumerate(names))
    raise ScenarioError(f"{source}: {key} must be one of {choices}, got {value!r}")


_RANGES: dict[str, tuple[float, float, str]] = {
    "utc_offset_h": (-14.0, 14.0, "hours from UTC"),
    "trees_per_km": (0.0, 500.0, "trees per km"),
    "visibility_m": (1.0, 1e6, "metres"),
    "rain_mm_per_h": (0.0, 200.0, "mm/h"),
    "snowfall_mm_per_h": (0.0, 50.0, "mm/h water equivalent"),
    "snow_cover": (0.0, 1.0, "a fraction"),
    "dirt": (0.0, 1.0, "a fraction"),
    "leaves_per_m2": (0.0, 20.0, "clumps per m2"),
    "exposure_ms": (0.01, 1000.0, "ms"),
    "gain": (0.01, 1000.0, "a factor"),
    "max_exposure_ms": (0.01, 1000.0, "ms"),
    "max_gain": (1.0, 1000.0, "a factor"),
    "full_well_e": (10.0, 1e7, "electrons"),
    "read_noise_e": (0.0, 1000.0, "electrons"),
}
_FLAGS = ("headlights", "platform_roofs", "auto_exposure", "noise", "motion_blur")
"""``auto_exposure`` may also be None (the light's default)."""


def _checked(key: str, value: Any, source: str) -> Any:
    if key == "light":
        if value not in get_args(Light):
            raise ScenarioError(f"{source}: light must be 'fixed' or 'sun', got {value!r}")
        return value
    if key == "season":
        return season_of(value, source)
    if key == "weather":
        return weather_of(value, source)
    if key == "auto_exposure" and value is None:
        return None
    if key in _FLAGS:
        if isinstance(value, str) and value.lower() in ("true", "false", "1", "0"):
            return value.lower() in ("true", "1")
        if not isinstance(value, bool | int) or value not in (0, 1):
            raise ScenarioError(f"{source}: {key} is true or false, got {value!r}")
        return bool(value)
    if key in ("day_of_year", "jpeg_quality", "seed"):
        low, high = {"day_of_year": (1, 366), "jpeg_quality": (0, 95), "seed": (0, 2**31 - 1)}[key]
        number = _number(key, value, source)
        if number != int(number) or not low <= number <= high:
            raise ScenarioError(
                f"{source}: {key} is a whole number from {low} to {high}, got {value!r}"
            )
        return int(number)
    bottom, top, unit = _RANGES[key]
    number = _number(key, value, source)
    if not bottom <= number <= top:
        raise ScenarioError(f"{source}: {key} is {unit}, from {bottom:g} to {top:g}, got {value!r}")
    return number


def _number(key: str, value: Any, source: str) -> float:
    if isinstance(value, str):
        with contextlib.suppress(ValueError):
            value = float(value)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(f"{source}: {key} must be a number, got {value!r}")
    return float(value)
