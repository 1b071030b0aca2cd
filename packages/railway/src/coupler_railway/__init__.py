"""Railway domain library: railML 2.x infrastructure, B-spline track model, balises, GeoJSON,
and the railway's message types for binary channels (``coupler_railway.messages``).

The track model needs the ``track`` extra (numpy, scipy, lxml); its names are imported on first
use, so a participant that only needs the messages (the OpenRails bridge) stays lean.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from coupler_railway.errors import RailMLError
    from coupler_railway.frame import LocalFrame
    from coupler_railway.geojson import to_geojson
    from coupler_railway.infrastructure import (
        Balise,
        BaliseGroup,
        Infrastructure,
        Network,
        PlatformEdge,
        Signal,
        Station,
        Switch,
        Track,
    )
    from coupler_railway.railml import load_infrastructure, load_network
    from coupler_railway.resources import BALISES_FILE, TRACK_FILE, write_fmu_resources
    from coupler_railway.track import (
        GradientChange,
        SectionGeometry,
        TrackModel,
        TrackPoint,
        TrackSection,
    )

_MODULE_OF = {
    "RailMLError": "errors",
    "LocalFrame": "frame",
    "to_geojson": "geojson",
    "Balise": "infrastructure",
    "BaliseGroup": "infrastructure",
    "Infrastructure": "infrastructure",
    "Network": "infrastructure",
    "PlatformEdge": "infrastructure",
    "Signal": "infrastructure",
    "Station": "infrastructure",
    "Switch": "infrastructure",
    "Track": "infrastructure",
    "load_infrastructure": "railml",
    "load_network": "railml",
    "BALISES_FILE": "resources",
    "TRACK_FILE": "resources",
    "write_fmu_resources": "resources",
    "GradientChange": "track",
    "SectionGeometry": "track",
    "TrackModel": "track",
    "TrackPoint": "track",
    "TrackSection": "track",
}


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'coupler_railway' has no attribute '{name}'")
    return getattr(importlib.import_module(f"coupler_railway.{module}"), name)


__all__ = [
    "BALISES_FILE",
    "TRACK_FILE",
    "Balise",
    "BaliseGroup",
    "GradientChange",
    "Infrastructure",
    "LocalFrame",
    "Network",
    "PlatformEdge",
    "RailMLError",
    "SectionGeometry",
    "Signal",
    "Station",
    "Switch",
    "Track",
    "TrackModel",
    "TrackPoint",
    "TrackSection",
    "load_infrastructure",
    "load_network",
    "to_geojson",
    "write_fmu_resources",
]
