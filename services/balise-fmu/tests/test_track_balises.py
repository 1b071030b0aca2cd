"""The TrackBalises FMU (FMI 2.0 and 3.0, one C model) on the railway test line.

    position --> [ TrackBalises ] --> last_balise_id, last_group_id, last_balise_distance,
                  antenna_offset       balises_passed, latitude, longitude, passed_in_step

Every expected balise comes from coupler_railway's balise table of the same railML file.
"""

from __future__ import annotations

import itertools
import shutil
from collections.abc import Callable
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu

from balise_fmu.build import FMU_SOURCES, main
from coupler_railway import Balise, Infrastructure
from coupler_tools.fmubuild import build_fmu

VERSIONS = [2, 3]
TEST_LINE = Path(__file__).resolve().parents[3] / "packages/railway/tests/data/test-line.railml"
Readings = Callable[..., list[tuple[int, int, float]]]


def table(balises: list[Balise]) -> list[tuple[int, int, float]]:
    return [(b.code, b.group, b.distance_m) for b in balises]


@pytest.mark.parametrize("version", VERSIONS)
def test_model_description_is_valid(fmus: dict[int, Path], version: int) -> None:
    assert validate_fmu(str(fmus[version])) == []
    md = fmpy.read_model_description(str(fmus[version]), validate=True)
    assert md.coSimulation.modelIdentifier == ("TrackBalises" if version == 2 else "TrackBalises3")
    names = {v.name: (v.causality, v.type) for v in md.modelVariables}
    assert names["position"][0] == "input"
    assert names["antenna_offset"][0] == "parameter"
    assert names["passed_in_step"] == ("output", "String")


@pytest.mark.parametrize("version", VERSIONS)
def test_forward_run_reads_every_balise_in_order(
    fmus: dict[int, Path],
    drive: Callable,
    parse_readings: Readings,
    balises: list[Balise],
    infrastructure: Infrastructure,
    version: int,
) -> None:
    length = infrastructure.model.length
    positions = [*np.arange(0.0, length, 50.0).tolist(), length]
    rows = drive(fmus[version], positions)

    assert parse_readings(rows) == table(balises)  # ids, groups and distances exact
    assert rows[0]["balises_passed"] == 0 and rows[0]["last_balise_id"] == 0
    assert rows[-1]["balises_passed"] == len(balises)
    last = balises[-1]
    assert (rows[-1]["last_balise_id"], rows[-1]["last_group_id"]) == (last.code, last.group)
    assert rows[-1]["last_balise_distance"] == last.distance_m
    # group C (1200, 1203, 1206 m) is crossed in the one step 1200 -> 1250 m
    group_c = [b for b in balises if b.group == 30]
    k = positions.index(1250.0)
    assert parse_readings([rows[k]]) == table(group_c)
    assert rows[k]["last_balise_id"] == group_c[-1].code
    assert rows[k]["last_balise_distance"] == group_c[-1].distance_m
    assert rows[k]["balises_passed"] - rows[k - 1]["balises_passed"] == 3
    # outputs hold between passes; balises_passed counts every reading
    for before, after in itertools.pairwise(rows):
        n = len(parse_readings([after]))
        assert after["balises_passed"] == before["balises_passed"] + n
        if n == 0:
            assert after["last_balise_id"] == before["last_balise_id"]


@pytest.mark.parametrize("version", VERSIONS)
def test_backward_run_reads_every_balise_in_reverse(
    fmus: dict[int, Path],
    drive: Callable,
    parse_readings: Readings,
    balises: list[Balise],
    infrastructure: Infrastructure,
    version: int,
) -> None:
    length = infrastructure.model.length
    positions = [length, *np.arange(1750.0, -1.0, -50.0).tolist()]
    rows = drive(fmus[version], positions)

    assert parse_readings(rows) == table(balises)[::-1]
    assert rows[-1]["balises_passed"] == len(balises)
    first = balises[0]
    assert (rows[-1]["last_balise_id"], rows[-1]["last_balise_distance"]) == (
        first.code,
        first.distance_m,
    )
    # group C backward in one step 1250 -> 1200 m: 303, 302, 301
    k = positions.index(1200.0)
    assert [r[0] for r in parse_readings([rows[k]])] == [303, 302, 301]
    assert rows[k]["last_balise_id"] == 301


@pytest.mark.parametrize("version", VERSIONS)
def test_everything_in_one_step_there_and_back(
    fmus: dict[int, Path],
    drive: Callable,
    parse_readings: Readings,
    balises: list[Balise],
    infrastructure: Infrastructure,
    version: int,
) -> None:
    rows = drive(fmus[version], [0.0, infrastructure.model.length, 0.0])
    assert parse_readings([rows[1]]) == table(balises)
    assert parse_readings([rows[2]]) == table(balises)[::-1]
    assert [r["balises_passed"] for r in rows] == [0, len(balises), 2 * len(balises)]


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("offset", [10.0, -5.0])
def test_antenna_offset_shifts_where_a_balise_is_read(
    fmus: dict[int, Path],
    drive: Callable,
    parse_readings: Readings,
    version: int,
    offset: float,
) -> None:
    # balise 101 at 100 m is read when position + offset reaches 100 m
    reached = 100.0 - offset
    positions = [reached - 2.0, reached - 1.0, reached, reached + 1.0]
    rows = drive(fmus[version], positions, antenna_offset=offset)
    assert [r["last_balise_id"] for r in rows] == [0, 0, 101, 101]
    assert parse_readings(rows) == [(101, 10, 100.0)]
    # and backward: unread again only once the antenna is back before 100 m
    rows = drive(fmus[version], [reached + 1.0, reached, reached - 0.5], antenna_offset=offset)
    assert [r["balises_passed"] for r in rows] == [0, 0, 1]


@pytest.mark.parametrize("version", VERSIONS)
def test_each_change_of_side_is_one_pass(
    fmus: dict[int, Path], drive: Callable, parse_readings: Readings, version: int
) -> None:
    # a balise at b is behind the antenna when antenna >= b; each change is one reading
    rows = drive(fmus[version], [99.0, 100.0, 100.0, 99.5, 99.9, 100.0, 101.0])
    assert [r["balises_passed"] for r in rows] == [0, 1, 1, 2, 2, 3, 3]
    assert [r[0] for r in parse_readings(rows)] == [101, 101, 101]
    assert rows[2]["passed_in_step"] == "" and rows[0]["passed_in_step"] == ""


@pytest.mark.parametrize("version", VERSIONS)
def test_latitude_longitude_follow_the_track(
    fmus: dict[int, Path],
    drive: Callable,
    balises: list[Balise],
    infrastructure: Infrastructure,
    version: int,
) -> None:
    length = infrastructure.model.length
    positions = [0.0, *[b.distance_m for b in balises], 777.7, length, length + 100.0, -50.0]
    rows = drive(fmus[version], positions)
    expected = infrastructure.model.coordinates(np.clip(np.array(positions), 0.0, length))
    got = np.array([[r["latitude"], r["longitude"]] for r in rows])
    # linear interpolation between 5 m samples: within a few millimetres of the B-spline
    assert got == pytest.approx(expected, abs=1e-7)
    for row, b in zip(rows[1 : 1 + len(balises)], balises, strict=True):
        assert (row["latitude"], row["longitude"]) == pytest.approx(
            (b.latitude_deg, b.longitude_deg), abs=1e-7
        )
    assert rows[0]["latitude"] == expected[0][0]  # samples are hit exactly


def test_fmi2_and_fmi3_agree(fmus: dict[int, Path], drive: Callable) -> None:
    positions = [0.0, 150.0, 1300.0, 90.0, 1785.0, 1201.0, 5.0]
    assert drive(fmus[2], positions, antenna_offset=3.0) == drive(
        fmus[3], positions, antenna_offset=3.0
    )


def test_simulate_fmu_with_a_position_signal(fmus: dict[int, Path], balises: list[Balise]) -> None:
    signal = np.array(
        [(0.0, 0.0), (1.0, 150.0), (2.0, 1300.0), (3.0, 90.0)],
        dtype=[("time", np.float64), ("position", np.float64)],
    )
    result = fmpy.simulate_fmu(str(fmus[2]), stop_time=4.0, output_interval=1.0, input=signal)
    # the outputs at t_k+1 are those of the position applied at t_k
    assert list(result["balises_passed"]) == [0, 0, 2, 6, 12]
    assert list(result["last_balise_id"]) == [0, 0, 102, 303, 101]
    assert result["last_balise_distance"][3] == balises[5].distance_m


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize(
    ("files", "message"),
    [
        ({"balises.csv": "balise_id,group_id,position_in_group,distance_m\n"}, "track.csv"),
        (
            {"track.csv": "distance_m,latitude_deg,longitude_deg\n0,50,12\n5,50,12.1\n"},
            "balises.csv",
        ),
        (
            {
                "track.csv": "distance_m,latitude_deg,longitude_deg\n0,50,12\n5,50,x\n",
                "balises.csv": "balise_id,group_id,position_in_group,distance_m\n",
            },
            "track.csv line 3",
        ),
        (
            {
                "track.csv": "distance_m,latitude_deg,longitude_deg\n0,50,12\n5,50,12.1\n",
                "balises.csv": "id,group,rank,distance\n",
            },
            "header is 'id,group,rank,distance'",
        ),
        (
            {
                "track.csv": "distance_m,latitude_deg,longitude_deg\n0,50,12\n5,50,12.1\n",
                "balises.csv": "balise_id,group_id,position_in_group,distance_m\n"
                "1,1,1,9\n2,1,2,3\n",
            },
            "balises.csv line 3: distance_m 3 is less than",
        ),
    ],
)
def test_missing_or_malformed_resources_are_reported(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    version: int,
    files: dict[str, str],
    message: str,
) -> None:
    resources = tmp_path / "resources"
    resources.mkdir()
    for name, text in files.items():
        (resources / name).write_text(text)
    folder = "TrackBalises" if version == 2 else "TrackBalises3"
    fmu = build_fmu(FMU_SOURCES / folder, tmp_path / f"{folder}.fmu", resources=resources)
    md = fmpy.read_model_description(str(fmu))
    unzipdir = fmpy.extract(str(fmu))
    # FMPy's default logger prints "[ERROR] message"; a custom logger would replace FMPy's
    # process-wide logger proxy and crash later FMUs once it is garbage-collected.
    try:
        with pytest.raises(Exception, match="instantiate"):
            fmpy.instantiate_fmu(unzipdir, md, fmi_type="CoSimulation")
    finally:
        shutil.rmtree(unzipdir, ignore_errors=True)
    out = capsys.readouterr().out
    assert "[ERROR]" in out and message in out, out


def test_build_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "nested" / "TB.fmu"
    assert main(["--railml", str(TEST_LINE), "--out", str(out), "--spacing", "10"]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    assert validate_fmu(str(out)) == []
    assert main(["--railml", str(tmp_path / "missing.railml"), "--out", str(out)]) == 1
    assert "missing.railml" in capsys.readouterr().err
