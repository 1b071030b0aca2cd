"""The detector on frames of the OpenRails mock: balises found where the railML file puts them.

    test line (railML) --> mock renderer --800 x 600 rgb--> detect() --> distance ahead

Balises 101 and 102 lie at 100 m and 103 m on the straight start of the test line; the train's
front (the camera) is placed so they are 8 to 40 m ahead.
"""

from __future__ import annotations

import numpy as np
import pytest

from coupler_railway import Infrastructure
from openrails_mock.renderer import Renderer
from perception.detector import Mounting, detect, ground_distance, yellow_mask

from .support import CAMERA, intrinsics


@pytest.mark.parametrize("ahead", [8.0, 15.0, 25.0, 33.0, 36.0])
def test_both_balises_of_a_group_are_found_at_their_distance(
    renderer: Renderer, test_line: Infrastructure, ahead: float
) -> None:
    first = next(b for b in test_line.balises if b.code == 101).distance_m
    front = first - ahead
    pixels = renderer.rgb(CAMERA, front)
    found = detect(pixels, intrinsics(), Mounting())
    truth = sorted(b.distance_m - front for b in test_line.balises if b.code in (101, 102))
    assert [round(d.distance_ahead_m) for d in found] == [round(t) for t in truth]
    for detection, expected in zip(found, truth, strict=True):
        assert detection.distance_ahead_m == pytest.approx(expected, abs=0.5)
        assert abs(detection.lateral_m) < 0.3  # between the rails of the straight
        assert detection.confidence > 0.5
        assert 250 < detection.top <= detection.bottom < 600  # below the horizon (row 249)


def test_nothing_is_found_where_no_balise_is_in_range(renderer: Renderer) -> None:
    pixels = renderer.rgb(CAMERA, 300.0)  # the next balise is 300 m ahead
    assert detect(pixels, intrinsics(), Mounting()) == []
    assert not yellow_mask(pixels).any()


def test_balises_beyond_the_range_are_not_reported(
    renderer: Renderer, test_line: Infrastructure
) -> None:
    first = next(b for b in test_line.balises if b.code == 101).distance_m
    pixels = renderer.rgb(CAMERA, first - 45.0)
    assert detect(pixels, intrinsics(), Mounting()) == []  # 40 m by default
    # farther, the two balises of the group (55 and 58 m ahead) are one blob: the limit
    pixels = renderer.rgb(CAMERA, first - 55.0)
    [merged] = detect(pixels, intrinsics(), Mounting(), max_range_m=70.0)
    assert 55.0 < merged.distance_ahead_m < 58.0


def test_a_synthetic_yellow_blob_is_placed_by_the_ground_plane() -> None:
    """A blob whose rows span exactly the balise at 20 m straight ahead, on a grey frame."""
    k, mount = intrinsics(), Mounting()
    pixels = np.full((600, 800, 3), 120, dtype=np.uint8)
    near = mount.height_m + 0.172  # the sleepers' top below the camera
    # rows of the near bottom edge (19.82 m) and the far top edge (20.18 m)
    pitch = np.radians(mount.pitch_deg)
    bottom = k.cy + k.fy * np.tan(np.arctan(near / 19.82) - pitch) - 0.5
    top = k.cy + k.fy * np.tan(np.arctan((mount.height_m + 0.072) / 20.18) - pitch) + 0.5
    pixels[round(top) : round(bottom) + 1, 390:410] = (236, 196, 24)
    [found] = detect(pixels, k, mount)
    assert found.distance_ahead_m == pytest.approx(20.0, abs=0.3)
    assert ground_distance(k.cx, k.cy - 60, near, k, mount) is None  # above the horizon (row 249)
