"""The world a camera sees: each condition checked against its physics on rendered frames.

    Scene (a straight line east from 50.58 N 13.0 E: balises at 70 and 130 m, a signal at
    80 m on the right, i.e. south) --> Renderer(conditions) --> frame, labels, depth frame

Fog lowers contrast as exp(-ln(20) d / visibility) (Koschmieder); a balise under 60 % snow
keeps 40 % of its yellow; shadows fall away from the sun; noise grows with gain; night is dark
but for the headlights; rain wets the ballast; motion blur smears with speed; dirt takes the
balises' colour; leaves add yellow where no balise is; JPEG loses detail with quality; the
labels are the depth frame's class/id pixels; the same seed gives the same bytes.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from openrails_mock.conditions import KOSCHMIEDER, Conditions
from openrails_mock.renderer import (
    BALISE,
    HAZE,
    SIGNAL,
    CameraModel,
    Frame,
    ObjectLabel,
    Renderer,
    View,
)
from openrails_mock.route import StraightRoute
from openrails_mock.scene import Scene, SceneBalise, SceneSignal
from openrails_mock.sun import sun_position

CAMERA = CameraModel(width=800, height=600, fov_deg=45.0)
NOON = View(clock_s=12 * 3600.0)


@pytest.fixture(scope="module")
def scene() -> Scene:
    route = StraightRoute(length_m=2000.0, heading_deg=90.0)  # east
    return Scene(
        route,
        balises=[SceneBalise(7, 70.0, "b7"), SceneBalise(9, 130.0, "b9")],
        signals=[SceneSignal(1, 80.0, 1.0, "s1")],
    )


def render(scene: Scene, front_m: float, view: View = NOON, **conditions: object) -> Frame:
    return Renderer(scene, conditions=Conditions(**conditions)).render(  # type: ignore[arg-type]
        CAMERA, front_m, view
    )


def label(frame: Frame, kind: str, ident: int) -> ObjectLabel:
    return next(x for x in frame.labels if (x.kind, x.id) == (kind, ident))


def yellow(pixels: npt.NDArray[np.uint8]) -> npt.NDArray[np.bool_]:
    r, g, b = (pixels[..., i].astype(int) for i in range(3))
    return (r > 150) & (g > 110) & (b < 90) & (r - b > 100)


def box_of(item: ObjectLabel) -> tuple[slice, slice]:
    left, top, right, bottom = item.box
    return slice(top, bottom + 1), slice(left, right + 1)


def test_the_same_seed_gives_the_same_bytes_and_another_seed_other_bytes(scene: Scene) -> None:
    everything = {"light": "sun", "season": "winter", "weather": "snow", "rain_mm_per_h": 2.0,
                  "visibility_m": 300.0, "dirt": 0.5, "leaves_per_m2": 0.5, "trees_per_km": 40.0,
                  "platform_roofs": True, "noise": True, "motion_blur": True,
                  "jpeg_quality": 80}  # fmt: skip
    view = View(clock_s=15 * 3600.0, elapsed_s=12.4, speed_mps=16.0)
    first = render(scene, 50.0, view, **everything)
    again = render(scene, 50.0, view, **everything)  # a new renderer: nothing shared
    assert first.pixels.tobytes() == again.pixels.tobytes()
    assert first.labels == again.labels
    other = render(scene, 50.0, view, **everything, seed=1)
    assert other.pixels.tobytes() != first.pixels.tobytes()
    later = render(scene, 50.0, View(clock_s=15 * 3600.0, elapsed_s=12.6, speed_mps=16.0),
                   **everything)  # fmt: skip
    assert later.pixels.tobytes() != first.pixels.tobytes()  # snow falls, noise is drawn anew


@pytest.mark.parametrize("conditions", ["clear", "everything"])
def test_two_render_threads_give_the_bytes_and_labels_of_one(scene: Scene, conditions: str) -> None:
    everything = {"light": "sun", "season": "winter", "weather": "snow", "rain_mm_per_h": 2.0,
                  "visibility_m": 300.0, "dirt": 0.5, "leaves_per_m2": 0.5, "trees_per_km": 40.0,
                  "platform_roofs": True, "noise": True, "motion_blur": True,
                  "jpeg_quality": 80}  # fmt: skip
    world = Conditions(**everything) if conditions == "everything" else Conditions()  # type: ignore[arg-type]
    one, two = Renderer(scene, conditions=world), Renderer(scene, conditions=world, threads=2)
    for k, front_m in enumerate((0.0, 20.0, 45.0, 60.0, 68.0, 110.0)):  # the split moves
        view = View(clock_s=15 * 3600.0, elapsed_s=0.4 * k, speed_mps=16.0)
        alone, shared = one.render(CAMERA, front_m, view), two.render(CAMERA, front_m, view)
        assert shared.pixels.tobytes() == alone.pixels.tobytes(), front_m
        assert shared.labels == alone.labels, front_m
        depth = one.depth(CAMERA, front_m, 60.0)
        assert two.depth(CAMERA, front_m, 60.0).tobytes() == depth.tobytes()
    assert two.with_conditions(Conditions()).bands is two.bands


def test_the_default_is_the_clear_noon_look_whatever_the_clock(scene: Scene) -> None:
    noon = render(scene, 50.0, NOON)
    night = render(scene, 50.0, View(clock_s=23 * 3600.0))
    assert noon.pixels.tobytes() == night.pixels.tobytes()
    assert (noon.exposure_ms, noon.gain) == (1.0, 1.0)


@pytest.mark.parametrize("visibility", [100.0, 250.0])
def test_fog_lowers_contrast_as_koschmieder_says(scene: Scene, visibility: float) -> None:
    """Per pixel of a balise: (fogged - airlight) / (clear - airlight) is the air's
    transmittance exp(-ln(20) d / visibility), at each distance."""
    for ahead in (15.0, 30.0, 50.0):
        front = 70.0 - ahead
        clear = render(scene, front, visibility_m=1e6)
        fog = render(scene, front, visibility_m=visibility)
        item = label(clear, "balise", 7)
        rows, cols = box_of(item)
        inside = yellow(clear.pixels)[rows, cols]
        blue_clear = clear.pixels[rows, cols, 2][inside].astype(float)
        blue_fog = fog.pixels[rows, cols, 2][inside].astype(float)
        measured = float(np.median((blue_fog - HAZE[2]) / (blue_clear - HAZE[2])))
        expected = math.exp(-KOSCHMIEDER * item.distance_m / visibility)
        assert measured == pytest.approx(expected, abs=0.02), ahead
        assert label(fog, "balise", 7).transmittance == pytest.approx(expected, rel=1e-6)


def test_a_balise_under_60_percent_snow_keeps_40_percent_of_its_yellow(scene: Scene) -> None:
    for ahead in (12.0, 20.0):
        bare = render(scene, 70.0 - ahead)
        snowed = render(scene, 70.0 - ahead, snow_cover=0.6)
        rows, cols = box_of(label(bare, "balise", 7))
        kept = yellow(snowed.pixels)[rows, cols].sum() / yellow(bare.pixels)[rows, cols].sum()
        assert kept == pytest.approx(0.4, abs=0.08), ahead
        item = label(snowed, "balise", 7)
        assert item.snow_pixels / item.pixels == pytest.approx(0.6, abs=0.08)
        assert item.visible_fraction == pytest.approx(0.4 * item.transmittance, abs=0.08)


def test_shadows_fall_on_the_side_away_from_the_sun(scene: Scene) -> None:
    """The signal stands south of the line (on its right, looking east). Its shadow lies
    north of it (left in the frame) all day; in the morning (sun in the south-east, ahead) it
    falls back towards the camera, in the afternoon (south-west, behind) away from it."""
    bare = Scene(StraightRoute(length_m=2000.0, heading_deg=90.0))
    centres = {}
    for hour in (9.5, 14.5):
        view = View(clock_s=hour * 3600.0)
        with_signal = render(scene, 55.0, view, light="sun", auto_exposure=False)
        without = render(bare, 55.0, view, light="sun", auto_exposure=False)
        signal = label(with_signal, "signal", 1)
        rows, cols = box_of(signal)
        darker = (
            with_signal.pixels.astype(int).sum(axis=2) < without.pixels.astype(int).sum(axis=2) - 30
        )
        darker[rows, cols] = False  # the signal itself
        found_rows, found_cols = np.nonzero(darker)
        assert len(found_rows) > 30, hour
        centres[hour] = (found_rows.mean(), found_cols.mean())
        assert centres[hour][1] < (cols.start + cols.stop) / 2  # north of the signal: left
        lat, lon = scene.place
        sun = sun_position(
            latitude_deg=lat,
            longitude_deg=lon,
            day_of_year=196,
            local_time_s=hour * 3600.0,
            utc_offset_h=1.0,
        )
        assert 90.0 < sun.azimuth_deg < 270.0  # in the south
    assert centres[9.5][0] > centres[14.5][0]  # morning: nearer the camera (lower in the frame)


def test_noise_variance_grows_with_gain_at_the_same_brightness(scene: Scene) -> None:
    """Shot noise (sqrt of the electrons) and read noise, in digital numbers: at gain g and
    the same mean, the variance is g * 255 / full_well * y + (g * 255 / full_well * read)^2."""
    variances = []
    for gain, exposure in ((1.0, 4.0), (4.0, 1.0)):
        conditions = {"noise": True, "gain": gain, "exposure_ms": exposure / 4.0}
        a = render(scene, 50.0, View(elapsed_s=1.0), **conditions).pixels.astype(float)
        b = render(scene, 50.0, View(elapsed_s=2.0), **conditions).pixels.astype(float)
        flat = slice(400, 600), slice(0, 150)  # grass: one colour, about 25 DN at this exposure
        variances.append(float(np.var(a[flat] - b[flat]) / 2.0))
        level = float(a[flat].mean())
        per_electron = gain * 255.0 / 10000.0
        expected = per_electron * level + (per_electron * 5.0) ** 2
        assert variances[-1] == pytest.approx(expected, rel=0.25), gain
    assert variances[1] > 3.0 * variances[0]


def test_night_is_dark_but_for_the_headlights(scene: Scene) -> None:
    night = View(clock_s=23.5 * 3600.0)
    dark = render(scene, 55.0, night, light="sun", headlights=False, auto_exposure=False)
    assert dark.pixels.mean() < 1.0
    lit = render(scene, 55.0, night, light="sun", auto_exposure=False, exposure_ms=20.0,
                 gain=32.0)  # fmt: skip
    track = lit.pixels[450:, 300:500].astype(float).mean()
    beside = lit.pixels[450:, :100].astype(float).mean()
    assert track > 20.0 and track > 4.0 * beside  # the beam along the track
    automatic = render(scene, 55.0, night, light="sun", headlights=False)
    assert (automatic.exposure_ms, automatic.gain) == (20.0, 32.0)  # it opens up, and no more
    day = render(scene, 55.0, NOON, light="sun")
    assert day.exposure_ms < 2.0 and day.gain == 1.0


def test_the_sun_stands_where_noaa_puts_it() -> None:
    """At solar noon the sun is 90 - latitude + declination high, due south."""
    for day, declination in ((172, 23.44), (80, 0.0), (355, -23.44)):
        noon = max(
            (sun_position(latitude_deg=50.58, longitude_deg=13.0, day_of_year=day,
                          local_time_s=t, utc_offset_h=1.0) for t in range(39600, 48600, 60)),
            key=lambda s: s.elevation_deg,
        )  # fmt: skip
        assert noon.elevation_deg == pytest.approx(90.0 - 50.58 + declination, abs=0.6)
        assert noon.azimuth_deg == pytest.approx(180.0, abs=1.5)
    morning = sun_position(latitude_deg=50.58, longitude_deg=13.0, day_of_year=172,
                           local_time_s=4.5 * 3600.0, utc_offset_h=1.0)  # fmt: skip
    assert 0.0 < morning.elevation_deg < 8.0 and 40.0 < morning.azimuth_deg < 70.0  # NE


def test_rain_darkens_the_ballast_and_the_air(scene: Scene) -> None:
    dry = render(scene, 50.0)
    wet = render(scene, 50.0, rain_mm_per_h=4.0)
    ballast = slice(520, 600), slice(330, 350)  # between the rails, near
    assert np.median(wet.pixels[ballast]) < 0.8 * np.median(dry.pixels[ballast])
    item = label(wet, "balise", 7)
    carbonneau = 1.076 * 4.0**0.67 / (10.0 * math.log10(math.e)) / 1000.0  # per m
    beta = KOSCHMIEDER / Conditions().visibility_m + carbonneau
    assert item.transmittance == pytest.approx(math.exp(-beta * item.distance_m), rel=1e-9)


def test_motion_blur_grows_with_speed_and_exposure(scene: Scene) -> None:
    near = slice(500, 600), slice(250, 550)  # the sleepers' edges near the camera

    def sharpness(frame: Frame) -> float:
        rows = frame.pixels[near].astype(float).mean(axis=2)
        return float((np.diff(rows, axis=0) ** 2).mean())  # gradient energy (a blur spreads it)

    camera = {"exposure_ms": 10.0, "gain": 0.1}  # as bright as 1 ms at gain 1
    still = render(scene, 50.0, View(speed_mps=0.0), motion_blur=True, **camera)
    assert still.pixels.tobytes() == render(scene, 50.0, **camera).pixels.tobytes()
    slow = render(scene, 50.0, View(speed_mps=10.0), motion_blur=True, **camera)
    fast = render(scene, 50.0, View(speed_mps=40.0), motion_blur=True, **camera)
    assert sharpness(still) > 1.3 * sharpness(slow) > 1.3 * sharpness(fast)


def test_dirt_takes_colour_and_leaves_add_yellow_where_no_balise_is(scene: Scene) -> None:
    clean = render(scene, 55.0)
    dirty = render(scene, 55.0, dirt=0.8)
    rows, cols = box_of(label(clean, "balise", 7))
    assert yellow(dirty.pixels)[rows, cols].sum() < 0.5 * yellow(clean.pixels)[rows, cols].sum()

    def stray(frame: Frame) -> int:
        mask = yellow(frame.pixels)
        for item in frame.labels:
            if item.pixels:
                r, c = box_of(item)
                mask[r, c] = False
        return int(mask.sum())

    assert stray(clean) == 0
    autumn = render(scene, 55.0, season="autumn")
    assert stray(autumn) > 20
    assert stray(render(scene, 55.0, season="autumn", leaves_per_m2=0.0)) == 0


def test_jpeg_loses_detail_with_quality(scene: Scene) -> None:
    raw = render(scene, 50.0).pixels.astype(float)

    def psnr(quality: int) -> float:
        lossy = render(scene, 50.0, jpeg_quality=quality).pixels.astype(float)
        return 10 * math.log10(255.0**2 / float(np.mean((lossy - raw) ** 2)))

    assert psnr(90) > 32.0 > psnr(10)


def test_the_labels_are_the_depth_frames_class_and_id_pixels(scene: Scene) -> None:
    renderer = Renderer(scene, conditions=Conditions(snow_cover=0.5, visibility_m=400.0))
    seen = 0
    for front in (50.0, 62.0, 110.0):
        frame = renderer.render(CAMERA, front)
        words = renderer.depth(CAMERA, front, 500.0)[..., 0]
        classes, ids = words >> 13, words & 0x1FFF
        for item in frame.labels:
            cls = {"balise": BALISE, "signal": SIGNAL}[item.kind]
            rows, cols = np.nonzero((classes == cls) & (ids == item.id))
            assert len(rows) == item.pixels, (front, item)
            if item.pixels:
                seen += 1
                assert (cols.min(), rows.min(), cols.max(), rows.max()) == item.box
            assert item.unoccluded_pixels >= item.pixels
    assert seen >= 5  # balise 7 and the signal twice, balise 9 three times
