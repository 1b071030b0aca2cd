"""TrackModel geometry: exact lengths of known shapes, projection round trips, lookups."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coupler_railway import Infrastructure, LocalFrame, SectionGeometry, TrackModel

ARC = 250.0 * math.pi  # quarter circle of radius 500 m


def test_straight_and_arc_have_their_exact_lengths(test_line: Infrastructure) -> None:
    straight, arc = test_line.model.sections
    assert (straight.track_id, arc.track_id) == ("t1", "t2")
    assert straight.start_distance == 0.0
    assert straight.length == pytest.approx(1000.0, abs=1e-3)
    assert arc.start_distance == pytest.approx(1000.0, abs=1e-3)
    assert arc.length == pytest.approx(ARC, abs=1e-3)
    assert test_line.model.length == pytest.approx(1000.0 + ARC, abs=1e-3)


def test_positions_follow_the_known_geometry(test_line: Infrastructure) -> None:
    model = test_line.model
    start = model.position(0.0)
    assert (start.latitude_deg, start.longitude_deg) == pytest.approx((50.0, 12.0), abs=1e-12)
    assert start.heading_deg == pytest.approx(90.0, abs=0.01)  # east
    middle = model.position(500.0)
    assert (middle.x_m, middle.y_m) == pytest.approx((500.0, 0.0), abs=1e-3)
    theta = 0.5  # 250 m into the arc
    on_arc = model.position(1000.0 + 500.0 * theta)
    expected = (1000.0 + 500.0 * math.sin(theta), 500.0 - 500.0 * math.cos(theta))
    assert (on_arc.x_m, on_arc.y_m) == pytest.approx(expected, abs=1e-3)
    assert on_arc.heading_deg == pytest.approx(90.0 - math.degrees(theta), abs=0.01)
    end = model.position(model.length)
    assert (end.x_m, end.y_m) == pytest.approx((1500.0, 500.0), abs=1e-6)
    assert end.heading_deg == pytest.approx(0.0, abs=0.01) or end.heading_deg == pytest.approx(
        360.0, abs=0.01
    )


@pytest.mark.parametrize("fixture", ["test_line", "scenario"])
def test_position_round_trips_through_project(fixture: str, request: pytest.FixtureRequest) -> None:
    model: TrackModel = request.getfixturevalue(fixture).model
    for distance in np.linspace(0.0, model.length, 301):
        point = model.position(float(distance))
        assert model.project(point.latitude_deg, point.longitude_deg) == pytest.approx(
            distance, abs=0.01
        )


def test_project_of_a_point_beside_the_track(test_line: Infrastructure) -> None:
    frame = test_line.model.frame
    lat, lon = frame.to_geographic(300.0, 12.0)  # 12 m north of the straight
    along, lateral = test_line.model.nearest(float(lat), float(lon))
    assert along == pytest.approx(300.0, abs=1e-3)
    assert lateral == pytest.approx(12.0, abs=1e-3)


def test_coordinates_is_the_vectorised_position(test_line: Infrastructure) -> None:
    model = test_line.model
    distances = np.array([0.0, 10.0, 1234.5, model.length])
    points = model.coordinates(distances)
    assert points.shape == (4, 2)
    for d, (lat, lon) in zip(distances, points, strict=True):
        p = model.position(float(d))
        assert (lat, lon) == pytest.approx((p.latitude_deg, p.longitude_deg), abs=1e-12)


def test_locate_names_the_section_and_offset(test_line: Infrastructure) -> None:
    model = test_line.model
    assert model.locate(0.0) == (0, 0.0)
    index, offset = model.locate(999.0)
    assert (index, offset) == (0, pytest.approx(999.0))
    index, offset = model.locate(1100.0)
    assert (index, offset) == (1, pytest.approx(100.0, abs=1e-3))
    assert model.locate(model.length)[0] == 1


def test_gradient_is_piecewise_constant(test_line: Infrastructure) -> None:
    model = test_line.model
    assert [model.gradient(d) for d in (0.0, 499.9, 500.0, 999.0, 1000.5, model.length)] == [
        0.0, 0.0, 10.0, 10.0, -5.0, -5.0,
    ]  # fmt: skip


def test_gradient_is_zero_without_changes() -> None:
    frame = LocalFrame(50.0, 12.0)
    lat, lon = frame.to_geographic([0.0, 100.0], [0.0, 0.0])
    model = TrackModel.build([SectionGeometry("a", "A", tuple(lat), tuple(lon))])
    assert model.length == pytest.approx(100.0, abs=1e-9)
    assert model.gradient(50.0) == 0.0


def test_distance_outside_the_track_is_rejected(test_line: Infrastructure) -> None:
    with pytest.raises(ValueError, match=r"distance -1\.0 m is outside the track"):
        test_line.model.position(-1.0)
    with pytest.raises(ValueError, match="outside the track"):
        test_line.model.gradient(test_line.model.length + 1.0)
