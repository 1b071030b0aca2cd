"""GeoJSON view of an infrastructure for maps (coordinates in lon, lat order per RFC 7946)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from coupler_railway.infrastructure import Infrastructure


def to_geojson(infrastructure: Infrastructure, *, spacing_m: float = 10.0) -> dict[str, Any]:
    """A FeatureCollection: the line (sampled every ``spacing_m``), balises and stations."""
    model = infrastructure.model
    count = max(2, math.ceil(model.length / spacing_m) + 1)
    points = model.coordinates(np.linspace(0.0, model.length, count))
    features: list[dict[str, Any]] = [
        {
            "type": "Feature",
            "geometry": {
                "type": "LineString",
                "coordinates": [[float(lon), float(lat)] for lat, lon in points],
            },
            "properties": {
                "kind": "track",
                "length_m": model.length,
                "sections": [
                    {
                        "track_id": s.track_id,
                        "name": s.name,
                        "start_distance_m": s.start_distance,
                        "length_m": s.length,
                    }
                    for s in model.sections
                ],
            },
        }
    ]
    features += [
        {
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": [b.longitude_deg, b.latitude_deg]},
            "properties": {
                "kind": "balise",
                "id": b.code,
                "railml_id": b.id,
                "code": b.code,
                "group": b.group,
                "position_in_group": b.position_in_group,
                "distance_m": b.distance_m,
                "name": b.name,
            },
        }
        for b in infrastructure.balises
    ]
    features += [
        {
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": [s.longitude_deg, s.latitude_deg]},
            "properties": {
                "kind": "station",
                "id": s.id,
                "name": s.name,
                "distance_m": s.distance_m,
            },
        }
        for s in infrastructure.stations
    ]
    return {"type": "FeatureCollection", "features": features}
