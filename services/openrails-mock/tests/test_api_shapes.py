"""The mock's JSON against schemas written from OpenRails' server source, not from the mock.

    test (aiohttp client) --HTTP--> openrails-mock --> JSON --> conforms(SCHEMA)

Sources read (DLR-SE/openrails-for-simulation, the simulation build with the lockstep API):

- ``Source/RunActivity/Viewer3D/WebServices/OutputGenerator.cs`` at commit
  d70c4f1814b00e10702f1ce5d1d5d5848f3cca30: the step reply ``{"trains": {name: train},
  "CameraSensors": {...}}``; per train ``location`` and ``carPositions.{Front,Rear}`` as
  ``WorldPosition2Dict`` (``tileX``, ``tileZ`` ints, ``x``, ``y``, ``z`` floats),
  ``trackLocation``/``rearTrackLocation`` from ``GetTravellerTrackLocation``
  (``movementDirection`` is ``traveller.Direction.ToString()``), ``rotation`` =
  ``FrontTDBTraveller.Rotation.Y`` (a float), ``locomotiveState`` (``SpeedMpS``,
  ``AccelerationMpSS``, ``DistanceM`` floats, ``WheelSlip``/``WheelSkid`` bools),
  ``trainLength.length``.
- ``Source/Orts.Simulation/Simulation/Traveller.cs`` at commit
  1c1fee6ae8b4b5280d98e766bcc60770181dc567: ``enum TravellerDirection { Backward = 0,
  Forward = 1 }``, so ``ToString()`` gives "Forward" or "Backward"; ``TrackNodeIndex`` and
  ``TrackVectorSectionIndex`` ints, ``TrackNodeLength``/``TrackNodeOffset`` floats, the
  offset counted in the traveller's direction; ``Rotation.Y`` wrapped to [-pi, pi], with
  (sin, cos) of it pointing (east, north).
- ``Source/RunActivity/Viewer3D/WebServices/WebServer.cs`` and ``ControlValue.cs`` at commit
  1c1fee6ae8b4b5280d98e766bcc60770181dc567: GET /API/TIME is a bare double, GET
  /API/CABCONTROLS a list of ``ControlValue {TypeName, MinValue, MaxValue, RangeFraction}``,
  GET /API/MAP a ``LatLonDirection {LatLon {Lat, Lon}, DirectionDeg}``, GET /API/MAP/INIT an
  ``InfoApiMap``, GET /API/TRAININFO a ``TrainInfo {ControlMode}``; Newtonsoft serializes
  public fields by name and enums as numbers.
- ``Source/ORTS.Common/InfoApiMap.cs`` (openrails/openrails at commit
  22f43400285c645d1fb30b3f85e14e9588f4cfdb, the class the simulation build uses):
  ``TypeOfLocomotive``, ``PointOnApiMapList`` of ``{LatLon, Color, TypeOfPointOnApiMap,
  Name}``, ``LineOnApiMapList`` of ``{LatLonFrom, LatLonTo}``, ``LatMin/LatMax/LonMin/LonMax``.
- ``Dlr/simulation_client/model/train.py`` at d70c4f1814b00e10702f1ce5d1d5d5848f3cca30 (the
  public Python client): reads ``location`` as (x + 2048 (tileX - start tile), z + 2048
  (tileZ - start tile), y) and compares ``movementDirection`` with "Backward".

Floats must arrive as JSON floats (Newtonsoft writes ``0.0``, never ``0``), ints as ints.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import aiohttp

from openrails_mock.config import MockConfig
from openrails_mock.route import StraightRoute

from .support import Serve, body

TILE = 2048.0
START_TILE = (-5354, 14849)  # DEFAULT_START_TILE of the public client (routecreation)


@dataclass(frozen=True)
class OneOf:
    """A string out of a fixed set (a C# enum's ToString())."""

    values: tuple[str, ...]


@dataclass(frozen=True)
class MapOf:
    """A JSON object with any keys, each value of ``schema``."""

    schema: Any


Schema = Any

WORLD_POSITION: Schema = {"tileX": int, "tileZ": int, "x": float, "y": float, "z": float}
TRACK_LOCATION: Schema = {
    "trackNodeIndex": int,
    "trackNodeLength": float,
    "trackNodeOffset": float,
    "trackVectorSectionIndex": int,
    "movementDirection": OneOf(("Forward", "Backward")),
}
TRAIN: Schema = {
    "location": WORLD_POSITION,
    "trackLocation": TRACK_LOCATION,
    "rearTrackLocation": TRACK_LOCATION,
    "rotation": float,
    "locomotiveState": {
        "v": float,
        "a": float,
        "distance": float,
        "wheelslip": bool,
        "wheelskid": bool,
    },
    "trainLength": {"length": float},
    "carPositions": {"Front": WORLD_POSITION, "Rear": WORLD_POSITION},
}
CAMERA_SENSOR: Schema = {"height": int, "width": int, "h_scale": float, "v_scale": float}
STEP_REPLY: Schema = {"trains": MapOf(TRAIN), "CameraSensors": MapOf(CAMERA_SENSOR)}
LAT_LON: Schema = {"Lat": float, "Lon": float}
SCHEMAS: dict[str, Schema] = {
    "/API/TIME": float,
    "/API/CABCONTROLS": [
        {"TypeName": str, "MinValue": float, "MaxValue": float, "RangeFraction": float}
    ],
    "/API/MAP": {"LatLon": LAT_LON, "DirectionDeg": float},
    "/API/MAP/INIT": {
        "TypeOfLocomotive": OneOf(("steam", "diesel", "electric")),
        "PointOnApiMapList": [
            {"LatLon": LAT_LON, "Color": str, "TypeOfPointOnApiMap": int, "Name": str}
        ],
        "LineOnApiMapList": [{"LatLonFrom": LAT_LON, "LatLonTo": LAT_LON}],
        "LatMin": float,
        "LatMax": float,
        "LonMin": float,
        "LonMax": float,
    },
    "/API/TRAININFO": {"ControlMode": str},
}


def problems(value: Any, schema: Schema, path: str = "$") -> list[str]:
    """Where ``value`` departs from ``schema``: exact keys, exact JSON types."""
    if isinstance(schema, dict):
        if not isinstance(value, dict):
            return [f"{path}: expected an object, got {value!r:.60}"]
        found = [f"{path}: missing '{k}'" for k in schema if k not in value]
        found += [f"{path}: unexpected '{k}'" for k in value if k not in schema]
        for key in schema.keys() & value.keys():
            found += problems(value[key], schema[key], f"{path}.{key}")
        return found
    if isinstance(schema, MapOf):
        if not isinstance(value, dict):
            return [f"{path}: expected an object, got {value!r:.60}"]
        return [p for k, v in value.items() for p in problems(v, schema.schema, f"{path}.{k}")]
    if isinstance(schema, list):
        if not isinstance(value, list) or not value:
            return [f"{path}: expected a non-empty list, got {value!r:.60}"]
        return [p for i, v in enumerate(value) for p in problems(v, schema[0], f"{path}[{i}]")]
    if isinstance(schema, OneOf):
        ok = isinstance(value, str) and value in schema.values
        return [] if ok else [f"{path}: expected one of {schema.values}, got {value!r}"]
    ok = isinstance(value, schema) and (schema is bool or not isinstance(value, bool))
    return [] if ok else [f"{path}: expected {schema.__name__}, got {value!r:.60}"]


def test_the_checker_catches_departures() -> None:
    """The schema check itself: the departures a real client would trip over are found."""
    good = {
        "trackNodeIndex": 1,
        "trackNodeLength": 10.0,
        "trackNodeOffset": 0.0,
        "trackVectorSectionIndex": 0,
        "movementDirection": "Forward",
    }
    assert problems(good, TRACK_LOCATION) == []
    assert problems(good | {"movementDirection": 1}, TRACK_LOCATION)
    assert problems(good | {"trackNodeOffset": 0}, TRACK_LOCATION)  # int where a float goes
    assert problems(good | {"trackNodeIndex": True}, TRACK_LOCATION)
    assert problems({k: v for k, v in good.items() if k != "trackNodeLength"}, TRACK_LOCATION)
    assert problems(good | {"extra": 1}, TRACK_LOCATION)


async def post(session: aiohttp.ClientSession, path: str, payload: Any) -> Any:
    async with session.post(path, json=payload) as resp:
        assert resp.status == 200, await resp.text()
        return await resp.json()


def config(**changes: Any) -> MockConfig:
    return MockConfig(loading_delay_s=0.0, **changes)


async def test_step_and_reset_replies_match_the_server_schema(serve: Serve) -> None:
    route = StraightRoute(length_m=6000.0, section_length_m=700.0, gradient_per_mille=5.0)
    async with serve(config(start_distance_m=3000.0), route=route) as session:
        replies = [await post(session, "/API/CABCONTROLS", body(THROTTLE=1.0))]
        replies += [await post(session, "/API/CABCONTROLS", body()) for _ in range(50)]
        replies.append(await post(session, "/API/CABCONTROLS", body(DIRECTION=-1, THROTTLE=1)))
        replies += [await post(session, "/API/CABCONTROLS", body()) for _ in range(200)]
        replies.append(await post(session, "/API/RESET", None))
    assert replies[-2]["trains"]["PLAYER"]["locomotiveState"]["v"] < 0.0  # reversing covered
    for i, reply in enumerate(replies):
        assert problems(reply, STEP_REPLY) == [], f"reply {i}"


async def test_get_endpoints_match_the_server_schemas(serve: Serve) -> None:
    async with serve(config(), route=StraightRoute(length_m=5000.0)) as session:
        await post(session, "/API/CABCONTROLS", body(THROTTLE=0.5))
        for path, schema in SCHEMAS.items():
            async with session.get(path) as resp:
                assert resp.status == 200, path
                assert problems(await resp.json(), schema, path) == []


async def test_map_init_draws_the_route(serve: Serve) -> None:
    route = StraightRoute(length_m=1000.0, origin_lat_deg=50.0, origin_lon_deg=13.0)
    async with serve(config(), route=route) as session, session.get("/API/MAP/INIT") as resp:
        info = await resp.json()
    lines = info["LineOnApiMapList"]
    assert lines[0]["LatLonFrom"] == {"Lat": 50.0, "Lon": 13.0}
    assert all(a["LatLonTo"] == b["LatLonFrom"] for a, b in itertools.pairwise(lines))
    end = route.position(1000.0)
    assert lines[-1]["LatLonTo"] == {"Lat": end.latitude_deg, "Lon": end.longitude_deg}
    assert len(info["PointOnApiMapList"]) == len(lines) + 1
    assert info["LatMin"] == end.latitude_deg and info["LatMax"] == 50.0  # heading south-west


def client_view(train: dict[str, Any]) -> dict[str, Any]:
    """What the public client (train.py) makes of a train record, written from its source."""
    loc = train["location"]
    east = loc["x"] + (loc["tileX"] - START_TILE[0]) * TILE
    north = loc["z"] + (loc["tileZ"] - START_TILE[1]) * TILE
    v = train["locomotiveState"]["v"]
    return {
        "location": (east, north, loc["y"]),
        "v": v,
        "front_offset": train["trackLocation"]["trackNodeOffset"],
        "front_backwards": train["trackLocation"]["movementDirection"] == "Backward",
        "rear_backwards": train["rearTrackLocation"]["movementDirection"] == "Backward",
        "rotation": train["rotation"],
    }


async def test_reverse_motion_is_visible_to_the_public_client(serve: Serve) -> None:
    """Reversing shows as OpenRails shows it: ``v`` < 0, the position and the node offset go
    back. ``movementDirection`` is the way the train faces on the node (OpenRails moves the
    travellers by a signed distance and never turns them when the train backs), so it stays."""
    route = StraightRoute(length_m=5000.0, section_length_m=1000.0, heading_deg=0.0)
    async with serve(config(start_distance_m=2500.0), route=route) as session:
        start = client_view((await post(session, "/API/RESET", {}))["trains"]["PLAYER"])
        seen = [await post(session, "/API/CABCONTROLS", body(DIRECTION=-1, THROTTLE=0.5))]
        seen += [await post(session, "/API/CABCONTROLS", body()) for _ in range(100)]
    views = [client_view(r["trains"]["PLAYER"]) for r in seen]
    last = views[-1]
    assert last["v"] < -1.0
    assert last["location"][1] < start["location"][1] - 50.0  # heading north, went south
    assert math.isclose(last["location"][0], start["location"][0], abs_tol=1e-6)
    assert last["front_offset"] < start["front_offset"] - 50.0
    assert all(math.isclose(v["rotation"], 0.0, abs_tol=1e-12) for v in views)
    assert not any(v["front_backwards"] or v["rear_backwards"] for v in views)
    # the client's own velocity: v along (cos, sin) of rotation -- here pointing backwards
    assert last["v"] * math.cos(last["rotation"]) < 0.0


async def test_nodes_laid_against_the_train_read_backward(serve: Serve) -> None:
    route = StraightRoute(length_m=5000.0, section_length_m=1000.0, heading_deg=200.0)
    cfg = config(start_distance_m=2500.0, track_nodes_reversed=True)
    async with serve(cfg, route=route) as session:
        train = (await post(session, "/API/CABCONTROLS", body()))["trains"]["PLAYER"]
    view = client_view(train)
    assert view["front_backwards"] and view["rear_backwards"]
    assert train["trackLocation"]["trackNodeOffset"] == 500.0  # counted the way it faces
    assert math.isclose(train["rotation"], math.radians(200.0) - 2 * math.pi)  # wrapped


async def test_location_is_in_openrails_world_tiles(serve: Serve) -> None:
    """x east and z north within a 2048 m tile, y up; tiles change where OpenRails' do."""
    route = StraightRoute(length_m=8000.0, gradient_per_mille=10.0, heading_deg=0.0)
    cfg = config(start_distance_m=3000.0, origin_tile_x=7, origin_tile_z=-3)
    async with serve(cfg, route=route) as session:
        train = (await post(session, "/API/RESET", {}))["trains"]["PLAYER"]
    lead = 3000.0 - 41.7 / 4  # the centre of the first of two cars
    loc = train["location"]
    assert (loc["tileX"], loc["tileZ"]) == (7, -3 + 1)  # 2990 m north: past the tile edge
    assert math.isclose(loc["z"], lead - TILE, abs_tol=1e-6)
    assert -TILE / 2 <= loc["z"] <= TILE / 2 and math.isclose(loc["x"], 0.0, abs_tol=1e-6)
    assert math.isclose(loc["y"], lead * 10.0 / 1000.0, rel_tol=1e-6)  # elevation, 10 per mille
    rear = train["carPositions"]["Rear"]
    assert math.isclose(rear["z"] + (rear["tileZ"] - loc["tileZ"]) * TILE, loc["z"] - 41.7 / 2)
