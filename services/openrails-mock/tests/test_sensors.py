"""Camera and depth sensors as OpenRails' build for simulation serves them.

    sensors.json --> openrails-mock (lockstep, railML test line) --HTTP--> test
                     CameraSensors in each reply; GET /API/CAMERASENSOR/<name>

The depth frames are decoded the way the public simulation client's ``LidarSensor`` does
(DLR-SE/openrails-for-simulation, ``Dlr/simulation_client/model/depthsensor.py`` and
``Dlr/Documentation/depth-sensors.md``): the configuration keys of ``CameraSensors``, the field
of view from ``h_scale``/``v_scale``, laser directions every 0.1 degree mapped to pixel indices
``round((1 + x') / 2 * w) + round((1 - y') / 2 * h) * w``, little-endian uint16 triples, class
in the top 3 bits. The test's own decoder is written from that documentation; it is the
client's format, not the mock's code. The point cloud must show the scene that was rendered:
the track under the train's path, each balise where the railML file puts it.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import aiohttp
import numpy as np
import pytest

from coupler.errors import ScenarioError
from coupler_railway import LocalFrame, load_infrastructure
from openrails_mock.config import MockConfig
from openrails_mock.sensors import load_sensors, parse_sensors

from .support import Serve, body

ROOT = Path(__file__).resolve().parents[3]
TEST_LINE = ROOT / "packages/railway/tests/data/test-line.railml"
HEIGHT, PITCH = 2.5, 4.0  # the mock's documented default mount (README: "Sensors")
TRACK, TERRAIN, BALISE = 2, 1, 6
CLIENT_DEFAULTS = {"h_scale": 1.81066, "v_scale": 2.414213}
"""The public client's DEFAULT_CONFIG for an 800 x 600 sensor with fov 45."""

SENSORS = [
    {"sensorName": "front", "sensorType": "rgb", "trainName": "PLAYER", "width": 800,
     "height": 600, "fov": 45.0},
    {"sensorName": "lidar", "sensorType": "depth", "trainName": "PLAYER", "width": 200,
     "height": 150, "fov": 45.0, "range": 200.0},
]  # fmt: skip


def sensors_file(tmp_path: Path, entries: Any = SENSORS) -> Path:
    path = tmp_path / "sensors.json"
    path.write_text(json.dumps(entries, indent=2))
    return path


def config(tmp_path: Path, **changes: Any) -> MockConfig:
    values: dict[str, Any] = {
        "loading_delay_s": 0.0,
        "railml": TEST_LINE,
        "sensors": sensors_file(tmp_path),
        "start_distance_m": 75.0,
    }
    values.update(changes)
    return MockConfig(**values)


async def frame(session: aiohttp.ClientSession, name: str) -> bytes:
    async with session.get(f"/API/CAMERASENSOR/{name}") as resp:
        assert resp.status == 200, await resp.text()
        data = await resp.read()
        assert resp.content_type == "application/octet-stream"
        assert resp.content_length == len(data)  # a plain body, not chunked
        assert "Transfer-Encoding" not in resp.headers
        return data


async def lockstep(session: aiohttp.ClientSession, **controls: float) -> dict[str, Any]:
    async with session.post("/API/CABCONTROLS", json=body(**controls)) as resp:
        assert resp.status == 200, await resp.text()
        reply: dict[str, Any] = await resp.json()
    return reply


# --- the client's way of reading a depth frame --------------------------------------------


def lidar_points(raw: bytes, entry: dict[str, Any], step_deg: float = 0.1) -> np.ndarray:
    """``(n, 5)`` rows (X right, Y up, Z away, class << 13 | id, intensity) of every point the
    frame has (no random drop-off), decoded as the simulation client's LidarSensor does."""
    width, height = entry["width"], entry["height"]
    h_scale, v_scale = entry["h_scale"], entry["v_scale"]
    max_distance = float(entry["max_distance"])
    h_fov = 2 * math.degrees(math.atan(1.0 / h_scale))
    v_fov = 2 * math.degrees(math.atan(1.0 / v_scale))
    h = np.radians(np.arange(-0.5 * h_fov, 0.5 * h_fov, step_deg))
    v = np.radians(np.arange(-0.5 * v_fov, 0.5 * v_fov, step_deg))
    h_angles, v_angles = (a.flatten() for a in np.meshgrid(h, v))
    fx = np.sin(h_angles) * np.cos(v_angles)
    fy = np.sin(v_angles)
    fz = np.cos(h_angles) * np.cos(v_angles)
    x_screen, y_screen = fx / fz * h_scale, fy / fz * v_scale
    inside = (y_screen >= -1.0) & (y_screen <= 1.0)

    def index(s: np.ndarray, n: int) -> np.ndarray:
        return np.clip(np.round((0.5 + 0.5 * s) * n), 0, n - 1).astype(int)

    at = index(x_screen[inside], width) + index(-y_screen[inside], height) * width
    words = np.frombuffer(raw, dtype="<u2")
    assert len(words) == 3 * width * height
    id_class = words[0::3][at]
    distance = words[1::3][at] * max_distance / 65535.0
    intensity = words[2::3][at] / 65535.0
    directions = np.column_stack([fx[inside], fy[inside], fz[inside]])
    keep = id_class != 0
    points = directions[keep] * distance[keep][:, None]
    return np.column_stack([points, id_class[keep], intensity[keep]])


def in_track_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lateral (right), ahead (along the track) and height above the top of the rails of
    camera-frame points, for the documented mount: 2.5 m up, pitched 4 degrees down."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    p = math.radians(PITCH)
    ahead = y * math.sin(p) + z * math.cos(p)
    up = y * math.cos(p) - z * math.sin(p)
    return x, ahead, HEIGHT + up


# --- configuration -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"sensorType": "thermal"}, "unknown sensorType 'thermal'; the sensor types are 'rgb'"),
        ({"width": 0}, "width must be 1 to 4096 pixels, got 0"),
        ({"height": 100_000}, "height must be 1 to 4096 pixels, got 100000"),
        ({"width": 4096, "height": 4096}, "is 16777216 pixels, more than the 8294400"),
        ({"width": 80.5}, "width must be a whole number of pixels, got 80.5"),
        ({"fov": 180}, "fov is the vertical field of view in degrees, between 0 and 180"),
        ({"range": 50.0}, "range applies to depth sensors only; remove it"),
        ({"trainName": "OTHER"}, "trainName 'OTHER' is not a train of this simulation"),
        ({"sensorName": "a/b"}, "sensorName must be 1 to 64 letters"),
        ({"fps": 30}, "unknown key 'fps'; an entry has sensorName, sensorType"),
    ],
)
def test_a_bad_sensor_entry_is_refused_naming_it(change: dict[str, Any], message: str) -> None:
    entry = {**SENSORS[0], **change}
    with pytest.raises(ScenarioError) as caught:
        parse_sensors([SENSORS[1], entry], source="sensors.json", train_name="PLAYER")
    assert message in str(caught.value)
    assert str(caught.value).startswith("sensors.json: sensor 1")


def test_bad_depth_range_duplicate_names_and_shapes_are_refused(tmp_path: Path) -> None:
    cases = [
        ([{**SENSORS[1], "range": 0}], "range is the depth sensor's reach in metres"),
        ([SENSORS[0], SENSORS[0]], "sensorName 'front' is used twice"),
        ({"sensorName": "front"}, "must be a JSON list of sensors"),
        ([{k: v for k, v in SENSORS[0].items() if k != "fov"}], "'fov' is missing"),
    ]
    for entries, message in cases:
        with pytest.raises(ScenarioError, match=message):
            parse_sensors(entries, source="s.json", train_name="PLAYER")
    broken = tmp_path / "broken.json"
    broken.write_text('[\n  {"sensorName": "front",\n  }\n]\n')
    with pytest.raises(ScenarioError, match=r"broken.json:3: the sensor configuration is not"):
        load_sensors(broken, train_name="PLAYER")
    with pytest.raises(ScenarioError, match="cannot read the sensor configuration"):
        load_sensors(tmp_path / "missing.json", train_name="PLAYER")


@pytest.mark.slow
def test_the_mock_refuses_a_bad_sensor_file_at_start_without_a_traceback(tmp_path: Path) -> None:
    path = sensors_file(tmp_path, [{**SENSORS[0], "sensorType": "lidar"}])
    done = subprocess.run(
        [sys.executable, "-m", "openrails_mock", "--port", "0", "--sensors", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1
    assert f"openrails-mock: error: {path}: sensor 0 ('front'): unknown sensorType 'lidar'" in (
        done.stderr
    )
    assert "Traceback" not in done.stderr


def test_sensors_need_lockstep_mode(tmp_path: Path) -> None:
    from openrails_mock.api import create_app

    with pytest.raises(ScenarioError, match="run the mock with --mode lockstep"):
        create_app(config(tmp_path, mode="stock"))


# --- the API -------------------------------------------------------------------------------


async def test_every_reply_describes_the_sensors_as_the_client_reads_them(
    serve: Serve, tmp_path: Path
) -> None:
    async with serve(config(tmp_path)) as session:
        async with session.post("/API/RESET") as resp:
            reset = await resp.json()
        reply = await lockstep(session, THROTTLE=0.5)
    for sensors in (reset["CameraSensors"], reply["CameraSensors"]):
        assert set(sensors) == {"front", "lidar"}
        front, lidar = sensors["front"], sensors["lidar"]
        assert set(front) == {"width", "height", "h_scale", "v_scale"}
        assert (front["width"], front["height"]) == (800, 600)
        for key, value in CLIENT_DEFAULTS.items():
            assert math.isclose(front[key], value, rel_tol=1e-5)
        assert set(lidar) == {"width", "height", "h_scale", "v_scale", "max_distance"}
        assert lidar["max_distance"] == 200.0
        assert math.isclose(lidar["h_scale"], lidar["v_scale"] * 150 / 200)


async def test_frames_have_the_declared_size_and_the_same_state_gives_the_same_bytes(
    serve: Serve, tmp_path: Path
) -> None:
    async with serve(config(tmp_path)) as session:
        first = await frame(session, "front")
        assert len(first) == 800 * 600 * 3
        assert len(await frame(session, "lidar")) == 200 * 150 * 6
        assert await frame(session, "front") == first
        for _ in range(10):
            await lockstep(session, THROTTLE=1.0)
        moved = await frame(session, "front")
        assert moved != first
        async with session.post("/API/RESET") as resp:
            assert resp.status == 200
        assert await frame(session, "front") == first


async def test_the_rgb_frame_shows_yellow_balises_between_the_rails(
    serve: Serve, tmp_path: Path
) -> None:
    async with serve(config(tmp_path)) as session:
        pixels = np.frombuffer(await frame(session, "front"), np.uint8).reshape(600, 800, 3)
    r, g, b = (pixels[..., i].astype(int) for i in range(3))
    yellow = (r > 180) & (g > 140) & (b < 80)
    rows, cols = np.nonzero(yellow)
    assert len(rows) > 20
    assert abs(cols.mean() - 399.5) < 20  # between the rails, on the straight
    assert rows.min() > 300  # below the horizon, on the ground
    assert (pixels[:100, :, 2] > pixels[:100, :, 0]).all()  # sky above


async def test_an_unknown_sensor_name_is_404_naming_the_configured_ones(
    serve: Serve, tmp_path: Path
) -> None:
    async with serve(config(tmp_path)) as session, session.get("/API/CAMERASENSOR/rear") as resp:
        assert resp.status == 404
        text = (await resp.json())["error"]
    assert text.startswith("No camera sensor named rear found")
    assert "configured: 'front', 'lidar'" in text
    async with serve(config(tmp_path, sensors=None)) as session:
        async with session.get("/API/CAMERASENSOR/front") as resp:
            assert resp.status == 404
            assert "configured: none" in (await resp.json())["error"]
        assert (await lockstep(session))["CameraSensors"] == {}


# --- the scene in the point cloud ----------------------------------------------------------


async def test_the_decoded_point_cloud_shows_the_track_and_the_balises(
    serve: Serve, tmp_path: Path
) -> None:
    infrastructure = load_infrastructure(TEST_LINE)
    front = 75.0  # on the straight, flat start of the test line
    async with serve(config(tmp_path, start_distance_m=front)) as session:
        entry = (await lockstep(session))["CameraSensors"]["lidar"]
        raw = await frame(session, "lidar")
    cloud = lidar_points(raw, entry)
    cls, ident = cloud[:, 3].astype(int) >> 13, cloud[:, 3].astype(int) & 0x1FFF
    lateral, ahead, height = in_track_frame(cloud[:, :3])
    assert set(np.unique(cls)) == {TERRAIN, TRACK, BALISE}

    track = cls == TRACK
    assert track.sum() > 1000
    # sleepers are 2.6 m long; a pixel of the 200 x 150 frame is 0.29 degrees wide, and the
    # client's index rounding moves a point by up to one pixel
    pixel = np.radians(0.6) * ahead[track]
    assert (np.abs(lateral[track]) < 1.3 + 0.1 + pixel).all()
    assert (height[track] < 0.05 + pixel).all() and (height[track] > -0.25 - pixel).all()
    assert ahead[track].min() < 8.0 and ahead[track].max() > 60.0  # under the path
    assert set(np.unique(ident[track])) == {1}  # the first railML track
    terrain = (cls == TERRAIN) & (ahead < 60.0)  # the line climbs farther on
    assert (height[terrain] < -0.15 + np.radians(0.6) * ahead[terrain]).all()

    seen = {}
    for balise in infrastructure.balises:
        mine = (cls == BALISE) & (ident == balise.code)
        expected = balise.distance_m - front
        if not 6.0 < expected < 60.0:
            assert not mine.any(), balise.code
            continue
        seen[balise.code] = int(mine.sum())
        # the distance a point carries is exact: within the balise's half length (0.18 m)
        # of the distance from the camera to the centre of its top
        centre = np.array([0.0, expected, -0.072 - HEIGHT])  # lateral, ahead, up
        distances = np.linalg.norm(cloud[mine, :3], axis=1)
        assert np.abs(distances - np.linalg.norm(centre)).max() < 0.2
        # its direction is the laser's, up to a pixel (0.3 degrees) from the pixel's, which
        # at a grazing angle moves a point along the track by up to d^2 / h * 0.005 rad
        smear = expected**2 / HEIGHT * np.radians(0.3)
        assert abs(np.median(ahead[mine]) - expected) < 0.2 + smear / 2
        assert np.abs(lateral[mine]).max() < 0.26 + 0.1
        assert (np.abs(height[mine] + 0.12) < 0.06 + smear * HEIGHT / expected).all()
    assert set(seen) == {101, 102} and min(seen.values()) >= 3
    intensity = cloud[:, 4]
    assert (intensity > 0).all() and (intensity <= 1).all()


async def test_balises_on_the_curve_are_where_the_railml_file_puts_them(
    serve: Serve, tmp_path: Path
) -> None:
    infrastructure = load_infrastructure(TEST_LINE)
    model = infrastructure.model
    front = 1180.0  # on the quarter circle, 20 m before balise group 301-303
    async with serve(config(tmp_path, start_distance_m=front)) as session:
        entry = (await lockstep(session))["CameraSensors"]["lidar"]
        raw = await frame(session, "lidar")
    cloud = lidar_points(raw, entry)
    cls, ident = cloud[:, 3].astype(int) >> 13, cloud[:, 3].astype(int) & 0x1FFF
    camera = np.append(model.local_xy([front])[0], HEIGHT)
    found = 0
    for balise in infrastructure.balises:
        mine = (cls == BALISE) & (ident == balise.code)
        if not 1190.0 < balise.distance_m < 1240.0:
            continue
        found += 1
        top = np.append(model.local_xy([balise.distance_m])[0], -0.072)
        # the camera's own height changes by the gradient over 20 m: within the tolerance
        expected = float(np.linalg.norm(top - camera))
        distances = np.linalg.norm(cloud[mine, :3], axis=1)
        assert mine.sum() >= 2, balise.code
        assert np.abs(distances - expected).max() < 0.5, (balise.code, distances, expected)
    assert found == 3


def straight_railml(tmp_path: Path) -> Path:
    """1000 m straight east with a balise at 70 m, a signal at 80 m (facing up: on the right)
    and a 0.55 m platform edge on the right from 40 to 100 m."""
    frame = LocalFrame(50.0, 12.0)

    def coord(x: float) -> str:
        lat, lon = frame.to_geographic(x, 0.0)
        return f'<geoCoord coord="{float(lat)!r} {float(lon)!r}"/>'

    path = tmp_path / "straight.railml"
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<railml xmlns="http://www.railml.org/schemas/2013" version="2.2">
  <infrastructure id="is"><tracks><track id="t1">
    <trackTopology>
      <trackBegin id="tb" pos="0">{coord(0.0)}</trackBegin>
      <trackEnd id="te" pos="1000">{coord(1000.0)}</trackEnd>
    </trackTopology>
    <trackElements><platformEdges>
      <platformEdge id="p1" pos="40" length="60" side="right" height="0.55"/>
    </platformEdges></trackElements>
    <ocsElements>
      <signals><signal id="s1" pos="80" dir="up"/></signals>
      <balises>
        <balise id="b1" code="7" pos="70"/>
        <baliseGroup id="g1" code="1"><baliseRef ref="b1"/></baliseGroup>
      </balises>
    </ocsElements>
  </track></tracks></infrastructure>
</railml>
""")
    return path


async def test_signals_and_platform_edges_are_in_the_point_cloud(
    serve: Serve, tmp_path: Path
) -> None:
    SIGNAL, UNKNOWN = 5, 0
    front = 50.0
    railml = straight_railml(tmp_path)
    async with serve(config(tmp_path, railml=railml, start_distance_m=front)) as session:
        entry = (await lockstep(session))["CameraSensors"]["lidar"]
        raw = await frame(session, "lidar")
    cloud = lidar_points(raw, entry)
    cls, ident = cloud[:, 3].astype(int) >> 13, cloud[:, 3].astype(int) & 0x1FFF
    lateral, ahead, height = in_track_frame(cloud[:, :3])
    signal = (cls == SIGNAL) & (ident == 1)
    assert signal.sum() >= 10
    assert np.median(ahead[signal]) == pytest.approx(80.0 - front, abs=0.5)
    assert np.median(lateral[signal]) == pytest.approx(3.2, abs=0.3)  # right of the track
    assert height[signal].max() > 4.5  # the head, 4 to 5.4 m up
    platform = (cls == UNKNOWN) & (ident == 1)
    assert platform.sum() >= 100
    # right, from its edge 1.7 m off the centre on (up to a pixel's smear)
    assert (lateral[platform] > 1.6 - np.radians(0.6) * ahead[platform]).all()
    assert np.abs(height[platform] - 0.55).min() < 0.05  # its top, 0.55 m up
    assert ahead[platform].max() < 100.0 - front + 1.0  # it ends at 100 m
    assert ((cls == BALISE) & (ident == 7)).any()
