"""The files OpenRails opens at start without checking they exist: environments and track types.

OpenRails' viewer opens ``ENVFILES\\<name>`` for the season and weather it starts in (the name
comes from the route file's ``Environment`` block: twelve entries, season by weather) and
``TTYPE.DAT`` (the track types the sound system indexes); a missing file stops the start.

An environment file is ``world ( world_sky ( world_sky_satellites ( N world_sky_satellite
(...) ) ) )`` as OpenRails' ``EnvironmentFile`` reads it: the sun (light 1) and the moon (light
0) with their rise and set times. No sky layers and no water layers are written: OpenRails'
own sky does not use them (only the viewer option that draws MSTS skies does, and it is not
supported by these routes), and a water layer is only drawn on terrain patches flagged as
water, which the route's terrain has none of.
"""

from __future__ import annotations

from pathlib import Path

from coupler_railway.openrails.stf import StfWriter, quote

SEASONS = ("Spring", "Summer", "Autumn", "Winter")
WEATHERS = (("Clear", "sun.env"), ("Rain", "rain.env"), ("Snow", "snow.env"))
"""The route file's entries per season, in the order MSTS writes them, and their files."""
SUN_RISE, SUN_SET = "06:00:00", "18:00:00"
TRACK_TYPE = "Coupler"
"""The one track type of TTYPE.DAT."""
TRACK_SOUNDS = ("CouplerTrackIn.sms", "CouplerTrackEx.sms")
"""Inside and outside track sound files TTYPE.DAT names (the route's SOUND folder; not written,
see docs/openrails-route.md)."""


def environment_entries() -> list[tuple[str, str]]:
    """``(SpringClear, sun.env), ...``: the route file's Environment block, twelve entries."""
    return [(f"{season}{weather}", env) for season in SEASONS for weather, env in WEATHERS]


def write_environments(folder: Path) -> list[str]:
    """``ENVFILES/*.env`` for every file the route file names; returns their names."""
    names = sorted({env for _, env in environment_entries()})
    for name in names:
        stf = StfWriter("JINX0E0t")
        stf.block("world")
        stf.block("world_sky")
        stf.block("world_sky_satellites", 2)
        for light, rise, set_ in ((1, SUN_RISE, SUN_SET), (0, SUN_SET, SUN_RISE)):
            stf.block("world_sky_satellite")
            stf.line("world_sky_satellite_light", light)
            stf.line("world_sky_satellite_rise_time", rise)
            stf.line("world_sky_satellite_set_time", set_)
            stf.end()
        stf.end()
        stf.end()
        stf.end()
        stf.save(folder / "ENVFILES" / name)
    return [f"ENVFILES/{name}" for name in names]


def write_track_types(folder: Path) -> None:
    """``TTYPE.DAT``: a count, then ``TrackType ( label inside.sms outside.sms )`` each."""
    stf = StfWriter("JINX0y0t")
    stf.values(1)
    stf.line("TrackType", quote(TRACK_TYPE), *(quote(s) for s in TRACK_SOUNDS))
    stf.save(folder / "TTYPE.DAT")
