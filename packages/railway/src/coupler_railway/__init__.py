"""Railway domain library: railML 2.x infrastructure, B-spline track model, balises, GeoJSON.

Standalone (numpy, scipy, lxml only): used by the OpenRails mock, the TrackBalises FMU build
and the map server.
"""

from __future__ import annotations

from coupler_railway.errors import RailMLError
from coupler_railway.frame import LocalFrame
from coupler_railway.geojson import to_geojson
from coupler_railway.infrastructure import Balise, BaliseGroup, Infrastructure, Station, Track
from coupler_railway.railml import load_infrastructure
from coupler_railway.resources import BALISES_FILE, TRACK_FILE, write_fmu_resources
from coupler_railway.track import (
    GradientChange,
    SectionGeometry,
    TrackModel,
    TrackPoint,
    TrackSection,
)

__all__ = [
    "BALISES_FILE",
    "TRACK_FILE",
    "Balise",
    "BaliseGroup",
    "GradientChange",
    "Infrastructure",
    "LocalFrame",
    "RailMLError",
    "SectionGeometry",
    "Station",
    "Track",
    "TrackModel",
    "TrackPoint",
    "TrackSection",
    "load_infrastructure",
    "to_geojson",
    "write_fmu_resources",
]
