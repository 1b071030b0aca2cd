"""GeoJSON and the FMU resource files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from coupler_railway import Infrastructure, to_geojson, write_fmu_resources


def test_geojson_shape(test_line: Infrastructure) -> None:
    collection = to_geojson(test_line)
    json.dumps(collection)  # serialisable as is
    assert collection["type"] == "FeatureCollection"
    kinds = [f["properties"]["kind"] for f in collection["features"]]
    assert kinds == ["track"] + ["balise"] * 7 + ["station"] * 2
    line = collection["features"][0]["geometry"]
    assert line["type"] == "LineString"
    assert len(line["coordinates"]) >= test_line.model.length / 10.0
    assert line["coordinates"][0] == pytest.approx([12.0, 50.0])  # lon, lat
    balise = collection["features"][1]
    assert balise["geometry"]["type"] == "Point"
    assert balise["geometry"]["coordinates"] == pytest.approx(
        [test_line.balises[0].longitude_deg, test_line.balises[0].latitude_deg]
    )
    assert balise["properties"] == {
        "kind": "balise",
        "id": 101,
        "railml_id": "b11",
        "code": 101,
        "group": 10,
        "position_in_group": 1,
        "distance_m": 100.0,
        "name": "A1",
    }
    station = collection["features"][-1]
    assert station["properties"]["name"] == "North"


def test_fmu_resource_files(test_line: Infrastructure, tmp_path: Path) -> None:
    track_path, balises_path = write_fmu_resources(test_line, tmp_path / "resources")
    track = track_path.read_bytes().decode("ascii")
    assert "\r" not in track and track.endswith("\n")
    lines = track.splitlines()
    assert lines[0] == "distance_m,latitude_deg,longitude_deg"
    rows = [[float(v) for v in line.split(",")] for line in lines[1:]]
    length = test_line.model.length
    assert len(rows) == math.ceil(length / 5.0) + 1
    assert [r[0] for r in rows[:3]] == [0.0, 5.0, 10.0]
    assert rows[-1][0] == length  # exactly, %.17g round-trips doubles
    assert rows[-2][0] == 1785.0
    assert rows[0][1:] == [50.0, 12.0]
    point = test_line.model.position(rows[100][0])
    assert rows[100][1:] == [point.latitude_deg, point.longitude_deg]

    balises = balises_path.read_text(encoding="ascii").splitlines()
    assert balises[0] == "balise_id,group_id,position_in_group,distance_m"
    assert balises[1:4] == ["101,10,1,100", "102,10,2,103", "201,20,1,600"]
    parsed = [line.split(",") for line in balises[1:]]
    assert [float(p[3]) for p in parsed] == [b.distance_m for b in test_line.balises]


def test_fmu_resources_with_exact_multiple_length(
    tmp_path: Path, test_line: Infrastructure
) -> None:
    track_path, _ = write_fmu_resources(test_line, tmp_path, spacing_m=test_line.model.length / 4)
    rows = track_path.read_text().splitlines()[1:]
    assert len(rows) == 5
    assert float(rows[-1].split(",")[0]) == test_line.model.length
