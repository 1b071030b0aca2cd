"""An exported route holds what OpenRails opens at start and draws, read by the mock's reader.

    railML --export_route--> ROUTE/ --openrails_mock.routefolder + .content--> what the test sees
                                    --simisa (second reader, where it covers a file)-->

Checked against the railML file's own geometry (its B-spline and gradients): every file is
read; the track's heights, pitches and the terrain under it within 1 cm; every dynamic
track's orientation within 0.01 degree of its section's pitch and heading; junctions drawn
by two-path track shapes; a file without its UTF-16 byte order mark refused.
"""

from __future__ import annotations

import gc
import math
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from coupler_railway import load_network
from coupler_railway.openrails.export import export_route
from openrails_mock.content import RouteContent, read_content, tile_name
from openrails_mock.routefolder import RouteFolder, load_route
from openrails_mock.stf import RouteError

ROOT = Path(__file__).resolve().parents[3]
JUNCTION = ROOT / "packages/railway/tests/data/junction.railml"
SCENARIO = ROOT / "scenarios/railway/data/annaberg-schwarzenberg.railml"
TILE = 2048.0


def exported(railml: Path, out: Path) -> tuple[RouteFolder, RouteContent]:
    export_route(railml, out)
    route = load_route(out)
    return route, read_content(route)


@pytest.fixture(scope="module")
def junction(tmp_path_factory: pytest.TempPathFactory) -> tuple[RouteFolder, RouteContent]:
    return exported(JUNCTION, tmp_path_factory.mktemp("routes") / "junction")


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> tuple[RouteFolder, RouteContent]:
    return exported(SCENARIO, tmp_path_factory.mktemp("routes") / "annaberg-schwarzenberg")


def heading_pitch(q: tuple[float, float, float, float]) -> tuple[float, float]:
    """Heading (clockwise from north) and pitch (OpenRails' AX: negative climbs) of the
    forward axis (0, 0, 1) turned by a QDirection quaternion (x, y, z, w)."""
    x, y, z, w = q
    forward = (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))
    return math.atan2(forward[0], forward[2]), -math.asin(max(-1.0, min(1.0, forward[1])))


def angle_error_deg(a: float, b: float) -> float:
    return abs(math.degrees((a - b + math.pi) % (2 * math.pi) - math.pi))


def test_the_folder_holds_what_openrails_opens(
    junction: tuple[RouteFolder, RouteContent],
) -> None:
    route, content = junction
    folder = route.folder
    assert sorted(content.environments) == ["rain.env", "snow.env", "sun.env"]
    assert all(count == 2 for count in content.environments.values())  # sun and moon
    assert content.track_types == [("Coupler", "CouplerTrackIn.sms", "CouplerTrackEx.sms")]
    assert (folder / "OpenRails" / "tsection.dat").is_file()
    placed = {o.file_name for o in route.objects.values() if o.kind != "Dyntrack"}
    assert placed == {"CouplerBalise.s", "CouplerSignal.s", "CouplerSwitch.s"}
    assert {f"SHAPES/{name}" for name in placed} <= set(content.shapes)
    balise = content.textures["TEXTURES/CouplerYellow.ace"]
    assert balise.pixels[0, 0].tolist() == [255, 204, 0, 255]  # yellow, as in the camera figure
    worlds = {(int(p.name[1:8]), int(p.name[8:15])) for p in (folder / "WORLD").glob("w*.w")}
    assert set(content.tiles) == worlds  # every tile with a world file has terrain
    assert content.consists == {
        "CouplerBR642": [
            "TRAINS/TRAINSET/CouplerBR642/CouplerBR642A.eng",
            "TRAINS/TRAINSET/CouplerBR642/CouplerBR642B.wag",
        ]
    }
    everything = {p for p in folder.rglob("*") if p.is_file()}
    assert everything - content.files == set()  # every file written is read
    trk = next(folder.glob("*.trk")).read_bytes()[2:].decode("utf-16-le")
    assert "TempRestrictedSpeed" not in trk
    sigcfg = (folder / "sigcfg.dat").read_bytes()[2:].decode("utf-16-le")
    assert "ScriptFile ( sigscr.dat )" in sigcfg
    assert "ScriptFiles ( 1" not in sigcfg  # OpenRails' grammar has no count there


def test_junctions_are_two_route_track_shapes(junction: tuple[RouteFolder, RouteContent]) -> None:
    route, _ = junction
    (index,) = route.junctions
    node = route.nodes[index]
    shape = route.track_shapes[node.shape or 0]
    assert shape.file_name == "CouplerSwitch.s"
    assert len(shape.paths) == 2 and shape.main_route == 0
    assert node.position is not None
    # the junction's UiD names the TrackObj drawing its shape, at the junction
    objects = [o for o in route.objects.values() if o.kind == "TrackObj"]
    assert len(objects) == 1 and objects[0].position == pytest.approx(node.position[2:], abs=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        from simisa import tsection, w

        loaded = tsection.load(str(route.folder / "OpenRails" / "tsection.dat"))
        shapes = loaded.trackshapes.track_shapes
        assert [len(s.section_idxs) for s in shapes.values()] == [2]
        tile = route.folder / "WORLD" / f"w{objects[0].tile[0]:+07d}{objects[0].tile[1]:+07d}.w"
        kinds = [type(o).__name__ for o in w.load(str(tile)).objects]
        assert "TrackObj" in kinds
        gc.collect()


def test_dyntracks_are_oriented_like_their_sections(
    junction: tuple[RouteFolder, RouteContent],
) -> None:
    _check_dyntracks(junction[0])


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_scenario_dyntracks_heights_and_pitch(scenario: tuple[RouteFolder, RouteContent]) -> None:
    """Every dynamic track of the 26 km line points along its section (pitch and heading within
    0.01 degree); every section starts at the railML height (altitude + gradients) within 1 cm
    and is pitched -atan(gradient)."""
    route, _ = scenario
    worst = _check_dyntracks(route)
    line = load_network(SCENARIO).lines[0]
    model = line.model
    assert line.altitude_m == 540.0
    distance, worst_height, worst_pitch = 0.0, 0.0, 0.0
    steps = model.gradient_steps
    for section in route.nodes[1].sections:
        expected = line.altitude_m + _climb(steps, distance)
        worst_height = max(worst_height, abs(section.y - expected))
        slope = model.gradient(distance + section.shape.length / 2.0)
        worst_pitch = max(worst_pitch, abs(section.ax + math.atan(slope / 1000.0)))
        distance += section.shape.length
    print(
        f"dyntracks vs sections: {worst:.2e} deg; heights vs railML: {worst_height * 1000:.2f} "
        f"mm; pitch vs gradient: {math.degrees(worst_pitch):.2e} deg"
    )
    assert worst_height <= 0.01
    assert math.degrees(worst_pitch) <= 0.01


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_scenario_terrain_lies_under_the_track(scenario: tuple[RouteFolder, RouteContent]) -> None:
    """Terrain samples within 8 m of the track are as high as the track's nearest point (railML
    heights, within 1 cm); between samples OpenRails' interpolation stays within 5 cm of the
    track everywhere along it; simisa reads the tiles alike."""
    route, content = scenario
    line = load_network(SCENARIO).lines[0]
    model = line.model
    distances = np.arange(0.0, model.length, 0.05)
    local = model.local_xy(distances)
    origin = (route.start[0] * TILE + route.start[2], route.start[1] * TILE + route.start[3])
    track = local + np.array(origin)
    breaks = np.array([d for d, _ in model.gradient_steps] + [model.length])
    climbs = np.array([_climb(model.gradient_steps, float(d)) for d in breaks])
    heights = line.altitude_m + np.interp(distances, breaks, climbs)
    tree = cKDTree(track)
    worst_sample = worst_under = 0.0
    checked = 0
    for (tile_x, tile_z), tile in content.tiles.items():
        index = np.arange(256)
        east, north = np.meshgrid(
            tile_x * TILE + index * 8.0 - 1024.0, tile_z * TILE + 1024.0 - index * 8.0
        )
        query = np.column_stack([east.ravel(), north.ravel()])
        near, nearest = tree.query(query, distance_upper_bound=8.0)
        close = near < 8.0
        if close.any():
            error = np.abs(tile.heights.ravel()[close] - heights[nearest[close]])
            worst_sample = max(worst_sample, float(error.max()))
            checked += int(close.sum())
    for point, height in zip(track[::200], heights[::200], strict=True):
        worst_under = max(worst_under, abs(_terrain_at(content, *point) - height))
    print(
        f"terrain: {len(content.tiles)} tiles; {checked} samples within 8 m of the track: "
        f"{worst_sample * 1000:.2f} mm from its height; interpolated under the track: "
        f"{worst_under * 1000:.1f} mm"
    )
    assert checked > 1000
    assert worst_sample <= 0.01
    assert worst_under <= 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        from simisa import terrain

        tile_x, tile_z = next(iter(content.tiles))
        loaded = terrain.load(str(route.folder / "TILES" / f"{tile_name(tile_x, tile_z)}.t"))
        samples = loaded.terrain_samples
        mine = content.tiles[(tile_x, tile_z)]
        assert np.float32(samples.terrain_sample_floor) == np.float32(mine.floor)
        assert np.float32(samples.terrain_sample_scale) == np.float32(mine.scale)
        gc.collect()


def test_shapes_read_by_simisa_alike(junction: tuple[RouteFolder, RouteContent]) -> None:
    route, content = junction
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        from simisa import shape

        for name, mine in content.shapes.items():
            theirs = shape.load(str(route.folder / name))
            assert len(theirs.points) == mine.points, name
            assert [str(i) for i in theirs.images] == list(mine.images), name
        gc.collect()


@pytest.mark.parametrize("name", ["junction.trk", "ENVFILES/sun.env", "SHAPES/CouplerBalise.s"])
def test_a_file_without_its_byte_order_mark_is_refused(
    junction: tuple[RouteFolder, RouteContent], tmp_path: Path, name: str
) -> None:
    """OpenRails reads a UTF-16 file without its byte order mark as UTF-8 and finds nothing in
    it (or refuses it: shapes, terrain, world): the mock refuses it, naming it."""
    copy = tmp_path / "junction"
    shutil.copytree(junction[0].folder, copy)
    target = copy / name
    target.write_bytes(target.read_bytes()[2:])
    with pytest.raises(RouteError, match="without its byte order mark") as raised:
        read_content(load_route(copy))
    assert str(raised.value).startswith(f"{target}:1: ")


# -- helpers ----------------------------------------------------------------------------------


def _climb(steps: tuple[tuple[float, float], ...], distance: float) -> float:
    """Height gained to ``distance`` along a line from its gradient steps (per mille)."""
    height = 0.0
    ends = [d for d, _ in steps[1:]] + [math.inf]
    for (start, slope), end in zip(steps, ends, strict=True):
        if distance <= start:
            break
        height += slope / 1000.0 * (min(distance, end) - start)
    return height


def _check_dyntracks(route: RouteFolder) -> float:
    """Largest angle between a Dyntrack's forward axis and its section's [deg]; asserts 0.01."""
    worst = 0.0
    for node in route.nodes.values():
        for section in node.sections:
            obj = route.objects[(*section.world_tile, section.world_uid)]
            assert obj.kind == "Dyntrack"
            heading, pitch = heading_pitch(obj.rotation)
            worst = max(worst, angle_error_deg(heading, section.ay))
            worst = max(worst, angle_error_deg(pitch, section.ax))
            assert obj.position[1] == pytest.approx(section.y, abs=1e-3)
    assert worst <= 0.01
    return worst


def _terrain_at(content: RouteContent, east: float, north: float) -> float:
    """The terrain's height at a world-plane point, interpolated as OpenRails' tile manager
    does (two triangles per sample square, split by the square's parity)."""
    tile_x, tile_z = math.floor(east / TILE + 0.5), math.floor(north / TILE + 0.5)
    x = (1024.0 + east - tile_x * TILE) / 8.0
    z = (1024.0 - (north - tile_z * TILE)) / 8.0

    def at(ix: int, iz: int) -> float:
        tx, tz = tile_x, tile_z
        while ix > 255:
            ix, tx = ix - 256, tx + 1
        while iz > 255:
            iz, tz = iz - 256, tz - 1
        return float(content.tiles[(tx, tz)].heights[iz, ix])

    ux, uz = math.floor(x), math.floor(z)
    nw, ne, sw, se = at(ux, uz), at(ux + 1, uz), at(ux, uz + 1), at(ux + 1, uz + 1)
    fx, fz = x - ux, z - uz
    if (ux & 1) == (uz & 1):
        if fx > fz:
            return nw + (ne - nw) * fx + (se - ne) * fz
        return nw + (se - sw) * fx + (sw - nw) * fz
    if fx + fz < 1:
        return nw + (ne - nw) * fx + (sw - nw) * fz
    return se + (sw - se) * (1 - fx) + (ne - se) * (1 - fz)
