"""The mock on a route folder written by hand here, not by Coupler's exporter.

    hand/ (hand.trk, hand.tdb, tsection.dat, PATHS/*.pat, WORLD/*.w, written below)
        --> openrails-mock (lockstep, port 0) <--HTTP: the public client's request shapes-- test

    node 5 (end) --[1: 200 m east]--> junction 4 --[2: 300 m east]--> node 6 (end)
                                                 \\--[3: arc R 200 m, 30 deg right]--> node 7 (end)

Junction 4: route 0 (pin 2, the left route) runs on east, route 1 (pin 3) turns right.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from openrails_mock.config import MockConfig
from openrails_mock.paths import load_path
from openrails_mock.routefolder import load_route
from openrails_mock.stf import MAX_FILE_BYTES, RouteError
from openrails_mock.tdb import TrackNetwork

from .support import (
    ARC_END,
    CAR,
    EAST,
    RADIUS,
    ROUTE_FILE,
    SECTIONS,
    TILE,
    WORLD,
    Serve,
    arc,
    body,
    pat,
    tdb,
    utf16,
)


@pytest.fixture
def route(tmp_path: Path) -> Path:
    """The hand-written route folder (some files in UTF-16 as MSTS writes them, some UTF-8)."""
    folder = tmp_path / "hand"
    (folder / "PATHS").mkdir(parents=True)
    (folder / "WORLD").mkdir()
    (folder / "hand.trk").write_bytes(utf16(ROUTE_FILE))
    (folder / "hand.tdb").write_bytes(utf16(tdb()))
    (folder / "tsection.dat").write_text(SECTIONS, encoding="utf-8")
    paths = {
        "straight": [(0.0, 0.0, "1 1"), (200.0, 0.0, "2 0"), (500.0, 0.0, "1 1")],
        "branch": [(0.0, 0.0, "1 1"), (200.0, 0.0, "2 0"), (*ARC_END, "1 1")],
        "back": [(500.0, 0.0, "1 1"), (200.0, 0.0, "2 0"), (0.0, 0.0, "1 1")],
        "missing-node": [(0.0, 0.0, "1 1"), (150.0, 0.0, "2 0"), (500.0, 0.0, "1 1")],
    }
    for name, points in paths.items():
        (folder / "PATHS" / f"{name}.pat").write_bytes(utf16(pat(name, points)))
    (folder / "WORLD" / "w-005354+014849.w").write_text(WORLD, encoding="utf-8")
    return folder


def config(route: Path, path: str, **extra: Any) -> MockConfig:
    return MockConfig(route=route, path=Path(f"PATHS/{path}.pat"), loading_delay_s=0.0, **extra)


async def drive_to(session: Any, front: float, **request: Any) -> dict[str, Any]:
    """Full throttle until the front passes ``front`` metres of route distance."""
    train: dict[str, Any] = {}
    for _ in range(600):
        payload = body(THROTTLE=1.0) | request
        async with session.post("/API/CABCONTROLS", json=payload) as resp:
            assert resp.status == 200, await resp.text()
            train = (await resp.json())["trains"]["PLAYER"]
        if 41.7 + train["locomotiveState"]["distance"] >= front:
            return train
    raise AssertionError("the train did not get there")


@pytest.mark.parametrize("junction", [None, 0, 1])
async def test_the_train_follows_the_junction(
    serve: Serve, route: Path, junction: int | None
) -> None:
    """Straight path, switch left alone, thrown to 0 (left: on east) or 1 (right: the arc),
    in the public client's shape: a dict with int keys, json-encoded (so keys are strings)."""
    switches = {} if junction is None else {4: junction}
    async with serve(config(route, "straight")) as session:
        request = json.loads(json.dumps({"SwitchCommands": switches}))
        train = await drive_to(session, 290.0, **request)
    front = 41.7 + train["locomotiveState"]["distance"]
    location = train["trackLocation"]
    lead = front - CAR / 2.0  # the lead car's centre, past the junction too
    if junction == 1:
        assert (location["trackNodeIndex"], location["movementDirection"]) == (3, "Forward")
        x, z = arc(lead - 200.0)
        heading = EAST + (front - 200.0) / RADIUS
    else:
        assert (location["trackNodeIndex"], location["movementDirection"]) == (2, "Forward")
        x, z, heading = lead, 0.0, EAST
    assert location["trackNodeOffset"] == pytest.approx(front - 200.0, abs=1e-6)
    assert (train["location"]["tileX"], train["location"]["tileZ"]) == TILE
    assert train["location"]["x"] == pytest.approx(x, abs=1e-4)
    assert train["location"]["z"] == pytest.approx(z, abs=1e-4)
    assert train["rotation"] == pytest.approx(heading, abs=1e-6)
    assert train["rearTrackLocation"]["trackNodeIndex"] in (1, location["trackNodeIndex"])


async def test_the_path_sets_its_junctions(serve: Serve, route: Path) -> None:
    async with serve(config(route, "branch")) as session:
        train = await drive_to(session, 290.0)
    assert train["trackLocation"]["trackNodeIndex"] == 3


async def test_bad_switch_commands_change_nothing(serve: Serve, route: Path) -> None:
    async with serve(config(route, "straight")) as session:
        for switches, message in (
            ({"9": 0}, "track node 9 is not a junction of hand.tdb (junctions: 4)"),
            ({"4": 2}, "junction 4 takes route 0 or 1"),
        ):
            payload = body(THROTTLE=1.0) | {"SwitchCommands": switches}
            async with session.post("/API/CABCONTROLS", json=payload) as resp:
                assert resp.status == 400
                assert message in (await resp.json())["error"]
        async with session.get("/API/CABCONTROLS") as resp:
            throttle = next(c for c in await resp.json() if c["TypeName"] == "THROTTLE")
        assert throttle["RangeFraction"] == 0.0  # the request's controls were not applied


def change(uid: int, **pose: float) -> dict[str, Any]:
    """The public simulation client's DynamicObject command."""
    values = {"x": 0.0, "y": 0.0, "z": 0.0, "yaw": 0.0, "pitch": 0.0, "roll": 0.0} | pose
    return {
        "Command": "ChangeObjectPosition",
        "UID": uid,
        "TileX": TILE[0],
        "TileZ": TILE[1],
    } | values


async def test_change_object_position(serve: Serve, route: Path) -> None:
    async with serve(config(route, "straight")) as session:
        async with session.get("/API/OBJECTS") as resp:
            before = await resp.json()
        assert [(o["UID"], o["x"], o["z"]) for o in before] == [(1, 250.0, 5.0)]  # animated only
        moved = change(1, x=260.5, y=1.0, z=-3.0, yaw=1.5)
        async with session.post("/API/CABCONTROLS", json=body() | {"Commands": [moved]}) as resp:
            assert resp.status == 200
        async with session.get("/API/OBJECTS") as resp:
            (box,) = await resp.json()
        assert (box["x"], box["y"], box["z"], box["yaw"]) == (260.5, 1.0, -3.0, 1.5)
        for command, message in (
            (change(2, x=1.0), "UID 2 in tile -5354 14849 (Static rock.s) is not animated"),
            (change(8, x=1.0), "no world object UID 8 in tile -5354 14849"),
            ({"Command": "Explode", "UID": 1}, "unknown Command 'Explode'"),
        ):
            payload = body() | {"Commands": [change(1, x=0.0), command]}
            async with session.post("/API/CABCONTROLS", json=payload) as resp:
                assert resp.status == 400
                assert message in (await resp.json())["error"]
        async with session.get("/API/OBJECTS") as resp:
            assert (await resp.json())[0]["x"] == 260.5  # all or nothing


async def test_other_trains_run_on_their_own_paths(
    serve: Serve, route: Path, tmp_path: Path
) -> None:
    trains = tmp_path / "trains.json"
    trains.write_text(
        json.dumps(
            [{"trainNumber": 1, "trainName": "AI1", "trainConfig": "any", "trainPath": "back"}]
        ),
        encoding="utf-8",
    )
    async with serve(config(route, "straight", trains=trains)) as session:
        ai = body(THROTTLE=1.0)
        for control in ai["Controls"]:
            control["LocomotiveName"] = "AI1"
        async with session.post("/API/CABCONTROLS", json=ai) as resp:
            reply = (await resp.json())["trains"]
        assert sorted(reply) == ["AI1", "PLAYER"]
        # AI1 faces west on node 2 (laid east): its offset counts from the node's far end
        assert reply["AI1"]["trackLocation"]["trackNodeIndex"] == 2
        assert reply["AI1"]["trackLocation"]["movementDirection"] == "Backward"
        for _ in range(150):  # 30 s: AI1 runs west through the junction (trailing) onto node 1
            async with session.post("/API/CABCONTROLS", json=ai) as resp:
                reply = (await resp.json())["trains"]
    ai1, player = reply["AI1"], reply["PLAYER"]
    assert player["locomotiveState"]["distance"] == 0.0  # the player's controls stay at rest
    travelled = ai1["locomotiveState"]["distance"]
    assert travelled > 300.0 - 41.7
    assert ai1["trackLocation"]["trackNodeIndex"] == 1
    assert ai1["trackLocation"]["movementDirection"] == "Backward"
    assert ai1["trackLocation"]["trackNodeOffset"] == pytest.approx(
        41.7 + travelled - 300.0, abs=1e-6
    )
    assert ai1["rotation"] == pytest.approx(-EAST, abs=1e-6)


def run_mock(*args: str) -> subprocess.CompletedProcess[str]:
    command = Path(sys.executable).with_name("openrails-mock")
    return subprocess.run(
        [str(command), "--port", "0", *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_a_path_through_a_missing_node_is_one_clear_error(route: Path) -> None:
    done = run_mock("--route", str(route), "--path", "PATHS/missing-node.pat")
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    pat_file = route / "PATHS" / "missing-node.pat"
    lines = pat_file.read_bytes()[2:].decode("utf-16-le").splitlines()
    line = next(i for i, text in enumerate(lines, start=1) if "150.0" in text)
    assert done.stderr == (
        f"openrails-mock: error: {pat_file}:{line}: the path runs through a junction at tile -5354 "
        "14849 x 150.0 z 0.0, but no junction node of hand.tdb is there; export the path with "
        "the route again, or move the point onto a junction\n"
    )


def _cut() -> str:
    text = tdb()
    return text[: text.index("TrackNode ( 4")]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("corrupted", "message"),
    [
        (lambda: tdb(pin_of_node_1=9), "track node 1 has a pin to node 9, which does not exist"),
        (_cut, "block TrackNodes is not closed"),
        (
            lambda: tdb().replace("1002 1002", "1003 1003"),
            "uses track section 1003, which no tsection.dat of the route defines",
        ),
    ],
)
def test_a_corrupted_track_database_is_one_clear_error(
    route: Path, corrupted: Any, message: str
) -> None:
    (route / "hand.tdb").write_bytes(utf16(corrupted()))
    done = run_mock("--route", str(route), "--path", "PATHS/straight.pat")
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    assert done.stderr.startswith(f"openrails-mock: error: {route / 'hand.tdb'}:")
    assert message in done.stderr
    assert done.stderr.count("\n") == 1


def test_stf_strings_the_exporter_quotes_read_back_whole(tmp_path: Path) -> None:
    """A name with quotes, a backslash, a newline or a tab is one STF string the reader gives
    back as written (a newline used to end up raw inside the file); a control character no
    STF reader decodes is written as a space."""
    from coupler_railway.openrails.stf import StfWriter, quote
    from openrails_mock.stf import read_stf

    name = 'A "quoted" \\ name\non two lines\tand a tab\x01'
    stf = StfWriter("JINX0r0t")
    stf.line("Name", quote(name))
    stf.line("Next", 1)
    path = stf.save(tmp_path / "x.trk")
    root = read_stf(path)
    assert root.block("Name").values == ['A "quoted" \\ name\non two lines\tand a tab ']
    assert root.block("Next").values == ["1"]
    assert "\n" not in path.read_bytes().decode("utf-16").split("Name (")[1].split(")")[0]


def _refs(count: int) -> str:
    return tdb().replace(
        "TrVectorNode ( TrVectorSections ( 1 1000",
        f"TrVectorNode ( TrItemRefs ( {count} ) TrVectorSections ( 1 1000",
    )


@pytest.mark.parametrize(
    ("file", "corrupted", "says"),
    [
        ("hand.tdb", lambda: utf16(_refs(2_000_000_000)), "declares 2000000000 items but holds 0"),
        (
            "tsection.dat",
            lambda: SECTIONS.replace("TrackSections ( 1002", "TrackSections ( 2147483647").encode(),
            "TrackSections declares 2147483647 as its highest index, but holds 1002",
        ),
        (
            "tsection.dat",
            lambda: SECTIONS.replace("1000 200 0", "1000 1e30 0").encode(),
            "track section 1000 is 1e+30 m long",
        ),
        (
            "PATHS/straight.pat",
            lambda: utf16(
                pat(
                    "straight", [(0.0, 0.0, "1 1"), (200.0, 0.0, "2 0"), (500.0, 0.0, "1 1")]
                ).replace("TrPathNodes ( 3", "TrPathNodes ( 3000000000")
            ),
            "TrPathNodes declares 3000000000 path nodes but holds 3",
        ),
    ],
)
def test_counts_and_lengths_written_in_route_files_are_checked(
    route: Path, file: str, corrupted: Any, says: str
) -> None:
    """A count that disagrees with what follows, or an absurd section, is a damaged file: one
    error naming it (they were read past in silence)."""
    (route / file).write_bytes(corrupted())
    with pytest.raises(RouteError) as caught:
        network = load_route(route)
        load_path(TrackNetwork(network), route / "PATHS" / "straight.pat")
    assert str(caught.value).startswith(str(route / file)), caught.value
    assert says in str(caught.value)


@pytest.mark.parametrize("kind", ["device", "huge"])
def test_a_route_file_that_is_no_file_or_huge_is_refused_unread(route: Path, kind: str) -> None:
    """A track database linked to /dev/zero (or any huge file) was read whole: MemoryError."""
    database = route / "hand.tdb"
    database.unlink()
    if kind == "device":
        database.symlink_to("/dev/zero")
    else:
        with database.open("wb") as sparse:
            sparse.truncate(MAX_FILE_BYTES + 1)
    with pytest.raises(RouteError) as caught:
        load_route(route)
    said = "is not a regular file" if kind == "device" else "is larger than 64 MB"
    assert said in str(caught.value)
