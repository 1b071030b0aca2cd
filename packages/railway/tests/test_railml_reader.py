"""railML reading: balises, groups, stations, warnings, and every error naming file:line."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from coupler_railway import Infrastructure, LocalFrame, RailMLError, load_infrastructure

ARC = 250.0 * math.pi
FRAME = LocalFrame(50.0, 12.0)


def test_balises_are_sorted_with_exact_distances(test_line: Infrastructure) -> None:
    rows = [(b.id, b.code, b.group, b.position_in_group) for b in test_line.balises]
    assert rows == [
        ("b11", 101, 10, 1),
        ("b12", 102, 10, 2),
        ("b21", 201, 20, 1),
        ("b31", 301, 30, 1),
        ("b32", 302, 30, 2),
        ("b33", 303, 30, 3),
        ("b41", 401, 40, 1),
    ]
    distances = [b.distance_m for b in test_line.balises]
    assert distances == sorted(distances)
    # pos, pos+absPos, absPos only, pos, then coordinates only (projected).
    expected = [100.0, 103.0, 600.0, 1200.0, 1203.0, 1206.0, 1500.0]
    assert distances == pytest.approx(expected, abs=1e-3)
    assert distances[:3] == [100.0, 103.0, 600.0]  # first section starts at exactly 0
    b11 = test_line.balises[0]
    assert (b11.name, b11.direction, b11.line) == ("A1", "up", b11.line)
    assert (b11.latitude_deg, b11.longitude_deg) == pytest.approx(
        tuple(float(v) for v in FRAME.to_geographic(100.0, 0.0)), abs=1e-9
    )


def test_groups_and_stations(test_line: Infrastructure) -> None:
    assert [(g.code, g.balise_ids) for g in test_line.groups] == [
        (10, ("b11", "b12")),
        (20, ("b21",)),
        (30, ("b31", "b32", "b33")),
        (40, ("b41",)),
    ]
    assert [(s.name, round(s.distance_m, 3)) for s in test_line.stations] == [
        ("West", 0.0),
        ("North", round(1000.0 + ARC, 3)),
    ]
    assert [t.id for t in test_line.tracks] == ["t1", "t2"]
    assert test_line.warnings == ()


def test_scenario_loads_with_enough_balises(scenario: Infrastructure) -> None:
    assert 25_000.0 <= scenario.model.length <= 30_000.0
    assert len(scenario.balises) >= 40
    assert len({b.code for b in scenario.balises}) == len(scenario.balises)
    assert len({g.code for g in scenario.groups}) == len(scenario.groups)
    assert all(1 <= len(g.balise_ids) <= 3 for g in scenario.groups)
    assert len(scenario.model.sections) >= 5
    names = [s.name for s in scenario.stations]
    assert names[0] == "Annaberg-Buchholz unt Bf"
    assert names[-1] == "Schwarzenberg (Erzgebirge)"
    first, last = scenario.model.position(0.0), scenario.model.position(scenario.model.length)
    assert (first.latitude_deg, first.longitude_deg) == pytest.approx((50.5766, 13.0104), abs=1e-3)
    assert (last.latitude_deg, last.longitude_deg) == pytest.approx((50.5447, 12.7857), abs=1e-3)
    assert any(scenario.model.gradient(d) != 0.0 for d in (100.0, 8000.0, 20000.0))
    assert scenario.warnings == ()


# -- bad files ---------------------------------------------------------------------------------


def _coord(x: float, y: float = 0.0) -> str:
    lat, lon = FRAME.to_geographic(x, y)
    return f'<geoCoord coord="{float(lat)!r} {float(lon)!r}"/>'


def _railml(balises: str = "", *, end: str | None = None, extra: str = "") -> str:
    """A 1000 m straight track; ``balises`` goes into ocsElements/balises."""
    end_coord = _coord(1000.0) if end is None else end
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<railml xmlns="http://www.railml.org/schemas/2013" version="2.2">
  <infrastructure id="is">
    <tracks>
      <track id="t1">
        <trackTopology>
          <trackBegin id="tb" pos="0" absPos="0">{_coord(0.0)}</trackBegin>
          <trackEnd id="te" pos="1000" absPos="1000">{end_coord}</trackEnd>
        </trackTopology>
        <ocsElements>
          <balises>
            {balises}
          </balises>
          {extra}
        </ocsElements>
      </track>
    </tracks>
  </infrastructure>
</railml>
"""


GROUP = '<baliseGroup id="g1" code="1"><baliseRef ref="b1"/></baliseGroup>'


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.railml"
    path.write_text(text, encoding="utf-8")
    return path


def _line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), start=1) if needle in line)


def _error(tmp_path: Path, text: str) -> RailMLError:
    path = _write(tmp_path, text)
    with pytest.raises(RailMLError) as info:
        load_infrastructure(path)
    assert info.value.file == str(path)
    assert str(info.value).startswith(f"{path}:{info.value.line}:")
    return info.value


def test_good_minimal_file_loads(tmp_path: Path) -> None:
    infra = load_infrastructure(
        _write(tmp_path, _railml('<balise id="b1" code="7" pos="10"/>' + GROUP))
    )
    assert [(b.code, b.distance_m) for b in infra.balises] == [(7, 10.0)]


def test_malformed_xml(tmp_path: Path) -> None:
    text = _railml().replace("</tracks>", "</trackz>")
    error = _error(tmp_path, text)
    assert error.line == _line_of(text, "</trackz>")
    assert error.element is None
    assert "malformed XML" in str(error) and "fix the XML syntax" in str(error)


def test_track_without_coordinates(tmp_path: Path) -> None:
    text = _railml().replace(_coord(0.0), "").replace(_coord(1000.0), "")
    error = _error(tmp_path, text)
    assert error.element == '<track id="t1">'
    assert error.line == _line_of(text, '<track id="t1">')
    assert "has no coordinates" in str(error)
    assert "geoMappings" in str(error)


def test_balise_pos_off_the_track(tmp_path: Path) -> None:
    text = _railml('<balise id="b1" code="7" pos="1200"/>' + GROUP)
    error = _error(tmp_path, text)
    assert error.element == '<balise id="b1">'
    assert error.line == _line_of(text, '<balise id="b1"')
    assert "lies off the track" in str(error) and "place it on track 't1'" in str(error)


def test_balise_coordinates_off_the_track(tmp_path: Path) -> None:
    text = _railml(f'<balise id="b1" code="7">{_coord(400.0, 30.0)}</balise>' + GROUP)
    error = _error(tmp_path, text)
    assert error.element == '<balise id="b1">'
    assert "its coordinates are 30.0 m from it" in str(error)


def test_balise_pos_disagrees_with_coordinates(tmp_path: Path) -> None:
    text = _railml(f'<balise id="b1" code="7" pos="300">{_coord(400.0)}</balise>' + GROUP)
    error = _error(tmp_path, text)
    assert "pos/absPos puts it at 300.000 m but its coordinates at 400.000 m" in str(error)


def test_pos_and_abs_pos_disagree(tmp_path: Path) -> None:
    text = _railml('<balise id="b1" code="7" pos="300" absPos="310"/>' + GROUP)
    error = _error(tmp_path, text)
    assert "pos 300.0 and absPos 310.0 disagree by 10.000 m" in str(error)


def test_declared_length_disagrees_with_coordinates(tmp_path: Path) -> None:
    error = _error(tmp_path, _railml(end=_coord(900.0)))
    assert error.element == '<trackEnd id="te">'
    assert "disagrees with its coordinates" in str(error)


def test_duplicate_ids(tmp_path: Path) -> None:
    text = _railml('<balise id="b1" code="7" pos="10"/><balise id="b1" code="8" pos="20"/>')
    error = _error(tmp_path, text)
    assert error.element == '<balise id="b1">'
    assert error.line == _line_of(text, 'code="8"')
    assert "duplicate id 'b1'" in str(error) and "unique id" in str(error)


def test_duplicate_balise_codes(tmp_path: Path) -> None:
    group = '<baliseGroup id="g1" code="1"><baliseRef ref="b1"/><baliseRef ref="b2"/></baliseGroup>'
    text = _railml('<balise id="b1" code="7" pos="10"/><balise id="b2" code="7" pos="13"/>' + group)
    error = _error(tmp_path, text)
    assert "balise code 7 is already used" in str(error)


def test_non_integer_code(tmp_path: Path) -> None:
    error = _error(tmp_path, _railml('<balise id="b1" code="A7" pos="10"/>' + GROUP))
    assert error.element == '<balise id="b1">'
    assert "code='A7' is not an integer" in str(error)


def test_balise_without_group(tmp_path: Path) -> None:
    error = _error(tmp_path, _railml('<balise id="b1" code="7" pos="10"/>'))
    assert "belongs to no baliseGroup" in str(error)


def test_unsupported_elements_are_warnings(tmp_path: Path) -> None:
    extra = (
        '<speedChanges><speedChange id="v1" pos="50" vMax="60"/>'
        '<speedChange id="v2" pos="60" vMax="80"/></speedChanges>'
    )
    text = _railml('<balise id="b1" code="7" pos="10"/>' + GROUP, extra=extra)
    infra = load_infrastructure(_write(tmp_path, text))
    assert len(infra.warnings) == 1
    assert "unsupported element <speedChanges> ignored" in infra.warnings[0]
    assert f":{_line_of(text, '<speedChanges>')}:" in infra.warnings[0]


SIGNALS = (
    '<signals><signal id="s1" name="A" pos="500" dir="up"/>'
    '<signal id="s2" pos="300" dir="down"/></signals>'
)
EDGES = (
    "</ocsElements><trackElements><platformEdges>"
    '<platformEdge id="p1" name="West 1" pos="20" length="120" side="right" height="0.55"/>'
    '<platformEdge id="p2" pos="900" length="100" side="left"/>'
    "</platformEdges></trackElements><ocsElements>"
)


def test_signals_and_platform_edges_are_placed(tmp_path: Path) -> None:
    text = _railml('<balise id="b1" code="7" pos="10"/>' + GROUP, extra=SIGNALS + EDGES)
    infra = load_infrastructure(_write(tmp_path, text))
    assert infra.warnings == ()
    assert [(s.id, s.name, s.distance_m, s.side) for s in infra.signals] == [
        ("s2", "s2", 300.0, "left"),
        ("s1", "A", 500.0, "right"),
    ]
    assert [(e.id, e.start_m, e.end_m, e.side, e.height_m) for e in infra.platform_edges] == [
        ("p1", 20.0, 140.0, "right", 0.55),
        ("p2", 900.0, 1000.0, "left", 0.76),  # the default height
    ]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ('<signals><signal id="s1" dir="up"/></signals>', "has neither pos/absPos nor geoCoord"),
        ('<signals><signal id="s1" pos="1200"/></signals>', "lies off the track"),
        (
            '<signals><signal id="s1" pos="5" dir="sideways"/></signals>',
            "dir 'sideways' is unknown",
        ),
        (EDGES.replace(' side="right"', ""), "side None is not 'left' or 'right'"),
        (EDGES.replace('length="100"', 'length="0"'), "has no positive length"),
        (EDGES.replace('length="100"', 'length="300"'), "runs 200.0 m past the end"),
        (EDGES.replace('height="0.55"', 'height="550"'), "height 550.0 m is not in (0, 2]"),
    ],
)
def test_bad_signals_and_platform_edges(tmp_path: Path, extra: str, message: str) -> None:
    text = _railml('<balise id="b1" code="7" pos="10"/>' + GROUP, extra=extra)
    error = _error(tmp_path, text)
    assert message in str(error)


def test_entities_are_not_expanded(tmp_path: Path) -> None:
    text = (
        _railml()
        .replace(
            '<?xml version="1.0" encoding="UTF-8"?>',
            '<?xml version="1.0"?>\n<!DOCTYPE railml [<!ENTITY x SYSTEM "file:///etc/passwd">]>',
        )
        .replace('<track id="t1">', '<track id="t1" name="&x;">')
    )
    error = _error(tmp_path, text)
    assert "external entity 'x'" in str(error)  # refused, never read
