"""export-openrails: the route folder read back by an independent reader, and its geometry.

    railML --coupler-railway export-openrails (the CLI)--> ROUTE/ --simisa--> what the test sees

The reader is simisa (PyPI), not the exporter's code: its track database, track section and
world file readers, and its generic block reader for paths and the route file. Section
geometry is evaluated here from OpenRails' rules (Traveller: a section starts at its X/Z with
heading AY and pitch AX; an arc of SectionCurve radius and signed angle, positive to the right).
"""

from __future__ import annotations

import gc
import math
import subprocess
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from simisa import tdb, tsection, w
from simisa.reader import BlockReader
from simisa.token_id import TokenID

from coupler_railway import load_network

DATA = Path(__file__).parent / "data"
JUNCTION = DATA / "junction.railml"
SCENARIO = (
    Path(__file__).resolve().parents[3] / "scenarios/railway/data/annaberg-schwarzenberg.railml"
)
TILE = 2048.0


def export(railml: Path, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    """The user's command, as a subprocess."""
    command = Path(sys.executable).with_name("coupler-railway")
    return subprocess.run(
        [str(command), "export-openrails", str(railml), "--out", str(out), *extra],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


@dataclass
class Route:
    """A route folder as simisa reads it."""

    folder: Path
    nodes: list  # simisa TrackNode, index i at position i - 1
    items: list
    sections: dict  # section index -> simisa track section
    origin: tuple[float, float]
    """RouteStart on the world plane [m]."""
    world: dict  # (tile_x, tile_z) -> simisa World
    paths: dict  # stem -> list of (tile_x, tile_z, x, y, z, flag1, flag2)

    def length(self, index: int) -> float:
        section = self.sections[index]
        if section.section_curve is None:
            return float(section.section_size.length)
        return float(section.section_curve.radius) * math.radians(abs(section.section_curve.angle))

    def node_length(self, node) -> float:
        return sum(self.length(v.section_index) for v in node.tr_vector_node.tr_vector_sections)


def read(folder: Path, name: str) -> Route:
    # simisa 0.1.0b2 leaves the files it reads open: let them go quietly here
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        route = _read(folder, name)
        gc.collect()
    return route


def _read(folder: Path, name: str) -> Route:
    database = tdb.load(str(folder / f"{name}.tdb"))
    sections = tsection.load(str(folder / "tsection.dat")).tracksections.track_sections
    start = None
    with BlockReader.open(str(folder / f"{name}.trk")) as reader:
        for block in reader:
            for sub in block:
                if sub.id == TokenID.RouteStart:
                    start = (sub.read_int(), sub.read_int(), sub.read_float(), sub.read_float())
                sub.skip()
    assert start is not None
    world = {}
    for path in sorted((folder / "WORLD").glob("w*.w")):
        loaded = w.load(str(path))
        world[(loaded.tile_x, loaded.tile_z)] = loaded
    paths = {}
    for path in sorted((folder / "PATHS").glob("*.pat")):
        pdps = []
        with BlockReader.open(str(path)) as reader:
            for block in reader:
                if block.id == TokenID.TrackPDPs:
                    for pdp in block:
                        pdps.append(
                            (pdp.read_int(), pdp.read_int(), pdp.read_float(), pdp.read_float(),
                             pdp.read_float(), pdp.read_int(), pdp.read_int())
                        )  # fmt: skip
                else:
                    block.skip()
        paths[path.stem] = pdps
    return Route(
        folder=folder,
        nodes=database.track_nodes,
        items=database.tr_item_table,
        sections=sections,
        origin=(start[0] * TILE + start[2], start[1] * TILE + start[3]),
        world=world,
        paths=paths,
    )


def section_points(route: Route, vs, offsets: np.ndarray) -> np.ndarray:
    """World-plane (x, z) of points ``offsets`` metres into a vector section, as OpenRails
    computes them (a section on a gradient is laid along the slope: horizontal cos(AX))."""
    section = route.sections[vs.section_index]
    if section.section_curve is None:
        right, ahead = np.zeros_like(offsets), offsets
    else:
        radius = float(section.section_curve.radius)
        sign = 1.0 if section.section_curve.angle > 0 else -1.0
        phi = offsets / radius
        right, ahead = sign * radius * (1.0 - np.cos(phi)), radius * np.sin(phi)
    ahead = ahead * math.cos(vs.ax)
    x0, z0 = vs.tile_x * TILE + vs.x, vs.tile_z * TILE + vs.z
    return np.column_stack(
        [
            x0 + right * math.cos(vs.ay) + ahead * math.sin(vs.ay),
            z0 - right * math.sin(vs.ay) + ahead * math.cos(vs.ay),
        ]
    )


def kinds(route: Route) -> list[str]:
    return [
        "vector" if n.tr_vector_node else "junction" if n.tr_junction_node else "end"
        for n in route.nodes
    ]


@pytest.fixture(scope="module")
def junction(tmp_path_factory: pytest.TempPathFactory) -> Route:
    out = tmp_path_factory.mktemp("routes") / "junction"
    done = export(JUNCTION, out)
    assert done.returncode == 0, done.stderr
    assert "3 vector, 1 junction, 3 end" in done.stdout
    return read(out, "junction")


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Route:
    out = tmp_path_factory.mktemp("routes") / "annaberg-schwarzenberg"
    done = export(SCENARIO, out)
    assert done.returncode == 0, done.stderr
    return read(out, "annaberg-schwarzenberg")


@pytest.mark.slow
def test_junction_nodes_and_pins(junction: Route) -> None:
    assert kinds(junction) == ["vector"] * 3 + ["junction"] + ["end"] * 3
    switch = junction.nodes[3]
    # trunk first: the main line before the switch (node 1) ends there; then the left route
    # (the main line on, node 2) and the right one (the branch, node 3), both begin there
    assert [(p.link, p.direction) for p in switch.tr_pins] == [(1, 0), (2, 1), (3, 1)]
    for index, node in enumerate(junction.nodes, start=1):
        for pin in node.tr_pins:  # every link is answered by a link back
            assert index in [p.link for p in junction.nodes[pin.link - 1].tr_pins]
    lengths = [junction.node_length(n) for n in junction.nodes[:3]]
    network = load_network(JUNCTION)
    assert lengths == pytest.approx([300.0, network.lines[0].model.length - 300.0,
                                     network.lines[1].model.length], abs=1e-3)  # fmt: skip


def test_junction_items_as_exported(junction: Route) -> None:
    network = load_network(JUNCTION)
    main, branch = network.lines
    refs = {}
    for index, node in enumerate(junction.nodes[:3], start=1):
        for ref in node.tr_vector_node.tr_item_refs:
            refs[ref] = index
    balises = {
        int(i.speed_ind): (refs[i.item_id], round(i.sdata1, 3))
        for i in junction.items
        if type(i).__name__ == "SpeedPostItem"
    }
    assert balises == {11: (1, 100.0), 12: (1, 103.0), 21: (2, 500.0), 31: (3, 150.0),
                       32: (3, 153.0)}  # fmt: skip
    signals = sorted(
        (refs[i.item_id], round(i.sdata1, 3), i.direction, i.signal_type)
        for i in junction.items
        if type(i).__name__ == "SignalItem"
    )
    assert signals == [(1, 250.0, 0, "couplermain"), (3, 300.0, 1, "couplermain")] or signals == [
        (1, 250.0, 0, "CouplerMain"),
        (3, 300.0, 1, "CouplerMain"),
    ]
    platforms = sorted(i.name for i in junction.items if type(i).__name__ == "PlatformItem")
    assert platforms == ["East", "East", "South", "South", "West", "West"]
    # every item lies on the railML track: its world position within 1 cm of the B-spline
    frame_origin = junction.origin
    for item in junction.items:
        if type(item).__name__ == "PlatformItem":
            continue
        node = refs[item.item_id]
        line, start = (main, 0.0) if node == 1 else (main, 300.0) if node == 2 else (branch, 0.0)
        east = item.tile_x * TILE + item.x - frame_origin[0]
        north = item.tile_z * TILE + item.z - frame_origin[1]
        expected = line.model.local_xy([start + item.sdata1])[0]
        side = 3.0 if type(item).__name__ == "SignalItem" else 0.0
        assert math.hypot(east - expected[0], north - expected[1]) == pytest.approx(side, abs=0.01)


def test_junction_world_objects_match_the_database(junction: Route) -> None:
    objects = {(tile, o.uid): o for tile, world in junction.world.items() for o in world.objects}
    dyntracks = [o for o in objects.values() if type(o).__name__ == "DynTrackObj"]
    vector_sections = [v for n in junction.nodes[:3] for v in n.tr_vector_node.tr_vector_sections]
    assert len(dyntracks) == len(vector_sections) == 17
    for v in vector_sections:  # each section names the world object that draws it
        drawn = objects[((v.wf_name_x, v.wf_name_z), v.wf_uid)]
        assert type(drawn).__name__ == "DynTrackObj"
        assert (drawn.position.x, drawn.position.z) == pytest.approx((v.x, v.z), abs=1e-3)
    balises = [o for o in objects.values() if type(o).__name__ == "StaticObj"]
    assert len(balises) == 5
    assert all(o.static_flags & 0x00080000 for o in balises)  # animated: movable by UID


def test_junction_paths_both_ways(junction: Route) -> None:
    assert sorted(junction.paths) == ["E-W", "S-W", "W-E", "W-S"]
    switch = junction.nodes[3].uid
    for stem, pdps in junction.paths.items():
        assert (pdps[0][5:], pdps[-1][5:]) == ((1, 1), (1, 1))  # start and end points
        assert [p[5:] for p in pdps[1:-1]] == [(2, 0)]  # the one junction they pass
        assert pdps[1][:5] == pytest.approx(
            (switch.tile_x, switch.tile_z, switch.x, switch.y, switch.z), abs=1e-3
        ), stem
    assert junction.paths["W-E"][0][:5] == pytest.approx(junction.paths["E-W"][-1][:5])


@pytest.mark.slow
def test_scenario_route_as_exported(scenario: Route) -> None:
    assert kinds(scenario) == ["vector", "end", "end"]
    infra = load_network(SCENARIO).lines[0]
    codes = sorted(int(i.speed_ind) for i in scenario.items if type(i).__name__ == "SpeedPostItem")
    assert codes == sorted(b.code for b in infra.balises)
    offsets = {
        int(i.speed_ind): i.sdata1 for i in scenario.items if type(i).__name__ == "SpeedPostItem"
    }
    # single precision, as OpenRails reads it: 2 mm steps beyond 16 km
    assert max(abs(offsets[b.code] - b.distance_m) for b in infra.balises) < 2e-3
    assert sorted(scenario.paths) == ["ocp_ABU-ocp_SZB", "ocp_SZB-ocp_ABU"]


@pytest.mark.slow
def test_round_trip_against_the_b_spline(scenario: Route, junction: Route) -> None:
    """Sample every exported section as OpenRails lays it and measure it against the railML
    B-spline at the same distance: across the track, and the length of the whole line."""
    cases = [
        (scenario, SCENARIO, [(0, 0.0)]),
        (junction, JUNCTION, [(0, 0.0), (0, 300.0), (1, 0.0)]),
    ]
    for route, railml, nodes in cases:
        lines = load_network(railml).lines
        worst_across = worst_along = 0.0
        length_error = total = 0.0
        for node, (line, start) in zip(route.nodes, nodes, strict=False):
            model = lines[line].model
            distance = start
            for vs in node.tr_vector_node.tr_vector_sections:
                length = route.length(vs.section_index)
                t = np.linspace(0.0, length, max(8, math.ceil(length / 0.25)) + 1)
                points = section_points(route, vs, t) - np.array(route.origin)
                along = np.minimum(distance + t, model.length)
                spline = model.local_xy(along)
                headings = model.headings(along)
                normal = np.column_stack([np.cos(headings), -np.sin(headings)])
                error = points - spline
                worst_across = max(worst_across, float(np.max(np.abs(np.sum(error * normal, 1)))))
                worst_along = max(worst_along, float(np.max(np.hypot(*error.T))))
                distance += length
            end = model.length if start > 0.0 or line > 0 or len(nodes) == 1 else 300.0
            length_error = max(length_error, abs(distance - end))
            total += distance - start
        per_km = length_error / (total / 1000.0)
        count = sum(len(n.tr_vector_node.tr_vector_sections) for n in route.nodes[: len(nodes)])
        print(
            f"{railml.name}: {count} sections; B-spline vs exported sections: max lateral"
            f" {worst_across * 1000:.2f} mm,"
            f" max distance at equal arc length {worst_along * 1000:.2f} mm, length error"
            f" {length_error * 1000:.3f} mm over {total / 1000:.3f} km ({per_km * 1000:.4f} mm/km)"
        )
        assert worst_across <= 0.01
        assert worst_along <= 0.01
        assert per_km <= 0.001


def _without_geometry(tmp_path: Path) -> Path:
    text = JUNCTION.read_text(encoding="utf-8")
    lines = [line for line in text.splitlines() if "<geoCoord" not in line]
    path = tmp_path / "no-geometry.railml"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def test_railml_without_geometry_is_one_clear_error(tmp_path: Path) -> None:
    bad = _without_geometry(tmp_path)
    done = export(bad, tmp_path / "route")
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1
    text = bad.read_text(encoding="utf-8").splitlines()
    line = next(i for i, t in enumerate(text, start=1) if '<track id="m1"' in t)
    assert done.stderr.startswith(f'error: {bad}:{line}: <track id="m1">: has no coordinates')
    assert not (tmp_path / "route").exists()  # nothing half-written


@pytest.mark.slow
def test_switch_to_nowhere_is_one_clear_error(tmp_path: Path) -> None:
    text = JUNCTION.read_text(encoding="utf-8").replace('ref="b1c"', 'ref="nowhere"')
    bad = tmp_path / "bad-switch.railml"
    bad.write_text(text, encoding="utf-8")
    done = export(bad, tmp_path / "route")
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    line = next(i for i, t in enumerate(text.splitlines(), start=1) if '<connection id="b1c"' in t)
    assert done.stderr == (
        f"error: {bad}:{line}: <connection id=\"b1c\">: ref 'sw1c' names a switch connection "
        "that does not refer back to it; set that switch connection's ref to 'b1c'\n"
    )


LINE = DATA / "test-line.railml"


@pytest.mark.parametrize("ident", ["../../PWNED", "{tmp}/ABSOLUTE", "a&#10;b", "CON", "x:y"])
def test_an_id_that_cannot_name_a_file_is_refused_with_its_line(tmp_path: Path, ident: str) -> None:
    """An ocp's id names the route's path files (``PATHS/<from>-<to>.pat``): an id with a
    path in it wrote outside the route folder (rc 0); now the export refuses it naming its
    line, and writes nothing at all."""
    ident = ident.format(tmp=tmp_path)
    text = LINE.read_text(encoding="utf-8").replace('<ocp id="ocpW"', f'<ocp id="{ident}"')
    bad = tmp_path / "bad.railml"
    bad.write_text(text, encoding="utf-8")
    done = export(bad, tmp_path / "out" / "route")
    assert done.returncode == 1, done.stdout
    line = next(i for i, t in enumerate(text.splitlines(), start=1) if "<ocp id=" in t)
    assert done.stderr.startswith(f"error: {bad}:{line}: <ocp id="), done.stderr
    assert "cannot be a file name in the route folder" in done.stderr
    assert "Traceback" not in done.stderr and done.stderr.count("\n") == 1
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["bad.railml"]
