"""Frames of the mock's cameras: the scene seen from the train's cab, rasterised on the CPU.

What is drawn (``scene``): the terrain, the ballast bed, sleepers (up to ``SLEEPER_RANGE_M``)
and the two rails along the line's B-spline (curves and gradients included), balises as yellow
boxes between the rails, signals beside the track and platform edges, each a flat-shaded
planar quad; with conditions (``conditions.Conditions``) also trees, platform roofs and
leaves on the ballast, all placed from the seed where the railML file has none.

How (``raster``, compiled kernels): every quad, in camera coordinates, is cut at the near
plane, projected with a pinhole camera and filled into an object-id buffer with a depth
buffer (1 / z, exact per pixel from the quad's plane); the terrain lies behind everything.
Per pixel one pass then finds the point the pixel sees (its exact distance), its colour, the
light it gets (sky, sun unless in a cast shadow, the train's headlights) and the air between
(haze, fog, rain and snow: Koschmieder's extinction towards the airlight). Then, as a camera
would: motion blur, rain streaks and snowflakes, exposure and gain (fixed or automatic),
shot and read noise, and optionally JPEG compression. The same state gives the same bytes.

Cast shadows are planar: each caster's quads (signals, platforms and their roofs, trees) are
projected along the sun onto the ground's level at the caster (``SHADOW_LEVEL_M`` below the
top of the rails), those shadow quads are filled into a mask of the frame, and the receivers
(terrain, track and balises, all within a few decimetres of that level) lose the sun's direct
light where the mask is set.

The camera (``Mount``) rides at the front of the train, ``height_m`` above the top of the
rails, looking along the track and pitched down by ``pitch_deg``; ``fov`` of a sensor is its
vertical field of view, pixels are square. Pixel centres follow a GPU's rasteriser: the
optical axis passes between the two middle columns and rows (OpenCV intrinsics
cx = width / 2 - 0.5, cy = height / 2 - 0.5), and a pixel shows what its centre sees.

Depth frames carry OpenRails' classes (``ObjectClassifiers`` of its Python client):
TERRAIN 1 (terrain and ballast), TRACK 2 (rails and sleepers; id = the route section's index
+ 1), SIGNAL 5 (id = the signal's number), UNKNOWN 0 for platforms (id = the platform edge's
number, never 0) and BALISE = CUSTOM1 6 (id = the balise's code, modulo 8192); trees and
leaves are TERRAIN. A pixel with nothing within ``max_distance`` (the sky) is all zeros.

Every colour frame has its ground truth (``Frame.labels``): each balise, signal and platform
edge in view with its box and pixels from the same id buffer, its distances, and the fraction
of it a camera can see (occlusion, snow, and the air's contrast loss).

Limits: the terrain is a fan around the camera at the track's height (a hill does not hide
the track behind it); no textures but the balises' snow; no other trains.
"""

from __future__ import annotations

import io
import math
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt
from PIL import Image

from . import raster
from .conditions import DEFAULT_VISIBILITY_M, KOSCHMIEDER, Conditions
from .scene import Scene
from .sun import AMBIENT_NOON, daylight, sun_position

FloatArray = npt.NDArray[np.float64]

# OpenRails' ObjectClassifiers (its Python client's depthsensor.py), and the mock's balises.
UNKNOWN = 0
TERRAIN = 1
TRACK = 2
SIGNAL = 5
BALISE = 6
"""CUSTOM1: the class the mock gives balises."""
ID_BITS = 13

GAUGE_M = 1.435
RAIL_HEAD_M = 0.072
RAIL_HEIGHT_M = 0.172
"""Top of rail above the top of the sleepers."""
SLEEPER_LENGTH_M = 2.6
SLEEPER_WIDTH_M = 0.26
SLEEPER_SPACING_M = 0.6
SLEEPER_RANGE_M = 80.0
"""Sleepers are drawn this far ahead; beyond, the bed has their mean colour."""
BALLAST_TOP_M = -0.2
BALLAST_HALF_WIDTH_M = 1.7
TERRAIN_M = -0.6
"""Terrain below the top of the rails."""
TERRAIN_HALF_WIDTH_M = 2.8
BALISE_ALONG_M = 0.36
BALISE_ACROSS_M = 0.52
BALISE_HEIGHT_M = 0.1
"""A Eurobalise on the sleepers between the rails: 0.36 m along, 0.52 m across the track,
its top 0.07 m below the top of the rails."""
SIGNAL_OFFSET_M = 3.2
PLATFORM_EDGE_M = 1.7
"""Platform edge from the track's centre line."""
PLATFORM_DEPTH_M = 3.0
ROOF_HEIGHT_M = 3.2
"""A platform roof above the platform's top."""
RANGE_M = 600.0
"""How far colour frames show the track."""
NEAR_M = 0.25
HAZE_M = 3000.0
"""The clear haze: extinction 1 / HAZE_M (``conditions.DEFAULT_VISIBILITY_M``)."""
SHADOW_LEVEL_M = -0.1
"""Cast shadows are laid on this level below the top of the rails."""
LEAVES_RANGE_M = 150.0
TREE_CELL_M = 100.0
LEAF_CELL_M = 10.0
LEAVES_HALF_WIDTH_M = 4.0
HEADLIGHT_CANDELA = 300_000.0
HEADLIGHT_HEIGHT_M = 1.0
HEADLIGHT_HALF_WIDTH_DEG = 8.0
NOON_LUX = 100_000.0
"""Illuminance of the clear noon the frames' colours stand for (relative light 1)."""
SNOW_CELLS = (9, 13)
"""A balise top's snow pattern: 4 cm cells, along x across."""
EXPOSURE_TARGET = 0.4 * 255.0

SKY_ZENITH = np.array([96.0, 140.0, 200.0])
SKY_HORIZON = np.array([196.0, 212.0, 228.0])
HAZE = np.array([190.0, 200.0, 210.0])
RAIN_AIR = np.array([168.0, 174.0, 180.0])
DUSK_HORIZON = np.array([236.0, 150.0, 96.0])
SUN = np.array([-0.45, -0.55, 0.70])
"""Towards the fixed clear-noon sun (world frame: east, north, up), unnormalised."""

GRASS = (88, 116, 60)
BALLAST = (128, 120, 110)
BALLAST_FAR = (112, 100, 90)
SHOULDER = (118, 110, 98)
SLEEPER = (92, 78, 66)
RAIL_TOP = (196, 196, 200)
RAIL_SIDE = (96, 72, 58)
BALISE_TOP = (236, 196, 24)
BALISE_SIDE = (206, 164, 14)
MAST = (150, 150, 150)
SIGNAL_HEAD = (30, 30, 30)
LAMP = (40, 220, 90)
PLATFORM_TOP = (170, 166, 160)
PLATFORM_EDGE = (140, 136, 130)
PLATFORM_LINE = (235, 235, 235)
ROOF = (110, 112, 118)
TRUNK = (84, 66, 50)
CROWN = (62, 96, 48)
SNOW = (238, 240, 245)
DIRT = (105, 92, 74)
LEAF_COLOURS = np.array(
    [(228, 186, 36), (236, 200, 52), (214, 150, 32), (190, 120, 40), (168, 104, 46)], float
)
"""Autumn leaves: the first two as yellow as a balise to a colour threshold."""

# kinds of faces: what they receive and how they are labelled
GROUND, CASTER, LAMP_FACE = 0, 1, 2
OBJECT_CLASSES = {BALISE: "balise", SIGNAL: "signal", UNKNOWN: "platform_edge"}


@dataclass(frozen=True, kw_only=True)
class Mount:
    """Where the cameras sit: at the train's front, above the rails, pitched down."""

    height_m: float = 2.5
    """Above the top of the rails."""
    pitch_deg: float = 4.0
    """Down from the track's direction."""


@dataclass(frozen=True, kw_only=True)
class CameraModel:
    """A sensor's image geometry: size and vertical field of view."""

    width: int
    height: int
    fov_deg: float

    @property
    def focal_px(self) -> float:
        """fx = fy [px]."""
        return self.height / 2.0 / math.tan(math.radians(self.fov_deg) / 2.0)

    def intrinsics(self) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) in OpenCV's convention (pixel centres at whole numbers)."""
        f = self.focal_px
        return f, f, self.width / 2.0 - 0.5, self.height / 2.0 - 0.5


@dataclass(frozen=True, kw_only=True)
class View:
    """The state a frame shows besides the place: time and motion."""

    elapsed_s: float = 0.0
    """Simulated time since the run's start: precipitation and noise are drawn for it."""
    clock_s: float = 12 * 3600.0
    """Time of day [s since midnight]: the sun's (light ``sun``)."""
    speed_mps: float = 0.0
    """The train's speed: motion blur."""


@dataclass(frozen=True)
class Pose:
    """A camera in the world: its position and axes (right, up, forward), world frame."""

    position: FloatArray
    right: FloatArray
    up: FloatArray
    forward: FloatArray

    def to_camera(self, points: FloatArray) -> FloatArray:
        """World points ``(..., 3)`` in camera coordinates: X right, Y up, Z forward."""
        rel = points - self.position
        return np.stack([rel @ self.right, rel @ self.up, rel @ self.forward], axis=-1)


@dataclass(frozen=True)
class ObjectLabel:
    """One labelled object in a frame (the ground truth of ``coupler.v1.ObjectLabel``)."""

    kind: str
    """``balise``, ``signal`` or ``platform_edge``."""
    id: int
    """Balise: its code (railML ``code``); signal and platform edge: its number on the line."""
    name: str
    """railML ``id``."""
    box: tuple[int, int, int, int]
    """Left, top, right, bottom pixel (inclusive) of its visible pixels; all -1: none."""
    pixels: int
    """Pixels that show it in this frame."""
    unoccluded_pixels: int
    """Pixels it would cover with nothing in front of it."""
    snow_pixels: int
    """Of ``pixels``, those under snow."""
    distance_along_m: float
    """Along the track from the camera (the train's front) to it (a platform edge: to its
    nearest point ahead)."""
    distance_m: float
    """Straight line from the camera to it (a balise: the centre of its top; a signal: its
    head; a platform edge: its nearest point ahead)."""
    transmittance: float
    """Contrast left after the air between: exp(-extinction * distance)."""

    @property
    def visible_fraction(self) -> float:
        """Of what it would show alone in clear air, the fraction a camera sees: pixels not
        occluded and not under snow, times the air's transmittance."""
        if self.unoccluded_pixels == 0:
            return 0.0
        return (self.pixels - self.snow_pixels) / self.unoccluded_pixels * self.transmittance


@dataclass(frozen=True)
class Frame:
    """A rendered colour frame and its ground truth."""

    pixels: npt.NDArray[np.uint8]
    labels: tuple[ObjectLabel, ...]
    exposure_ms: float
    gain: float


@dataclass
class _Faces:
    """Quads in world coordinates with what the kernels need per quad."""

    corners: list[FloatArray] = field(default_factory=list)
    colours: list[npt.NDArray[np.float64]] = field(default_factory=list)
    codes: list[npt.NDArray[np.int64]] = field(default_factory=list)
    order: list[FloatArray] = field(default_factory=list)
    """Rows (group, distance, layer): drawn by group, then farthest first, then by layer."""
    kinds: list[npt.NDArray[np.int64]] = field(default_factory=list)
    objects: list[npt.NDArray[np.int64]] = field(default_factory=list)
    textures: list[npt.NDArray[np.int64]] = field(default_factory=list)
    casters: list[FloatArray] = field(default_factory=list)
    """Quads that cast shadows, each with its ground level (n, 5, 3): corners, then level."""

    def add(
        self,
        corners: FloatArray,
        colour: tuple[int, int, int] | npt.ArrayLike,
        code: int | npt.NDArray[np.int64],
        *,
        group: float,
        distance: float | FloatArray,
        layer: float | FloatArray,
        kind: int = GROUND,
        obj: int = -1,
        texture: int | npt.NDArray[np.int64] = -1,
    ) -> None:
        n = len(corners)
        if n == 0:
            return
        self.corners.append(corners)
        self.colours.append(np.broadcast_to(np.asarray(colour, dtype=np.float64), (n, 3)))
        self.codes.append(np.broadcast_to(np.asarray(code, dtype=np.int64), (n,)))
        rows = np.empty((n, 3))
        rows[:, 0] = group
        rows[:, 1] = distance
        rows[:, 2] = layer
        self.order.append(rows)
        self.kinds.append(np.full(n, kind, dtype=np.int64))
        self.objects.append(np.full(n, obj, dtype=np.int64))
        self.textures.append(np.broadcast_to(np.asarray(texture, dtype=np.int64), (n,)))


@dataclass
class _Objects:
    """The frame's labelled objects, in the order their faces are added."""

    kinds: list[str] = field(default_factory=list)
    ids: list[int] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    along: list[float] = field(default_factory=list)
    anchors: list[FloatArray] = field(default_factory=list)

    def add(self, kind: str, ident: int, name: str, along: float, anchor: FloatArray) -> int:
        self.kinds.append(kind)
        self.ids.append(ident)
        self.names.append(name)
        self.along.append(along)
        self.anchors.append(anchor)
        return len(self.kinds) - 1


def code(cls: int, object_id: int) -> int:
    """A depth frame's first word: class in the top 3 bits, id in the low 13."""
    return (cls << ID_BITS) | (object_id & ((1 << ID_BITS) - 1))


@dataclass(frozen=True)
class _Light:
    sun: FloatArray
    """Towards the sun, world frame (unit)."""
    direct: FloatArray
    ambient: FloatArray
    shadows: bool
    lamp_candela: float
    emissive: float
    sky: FloatArray
    """(2, 3): horizon and zenith colour."""
    airlight: FloatArray


class Renderer:
    """Colour and depth frames of ``scene`` from a camera on ``mount`` under ``conditions``."""

    def __init__(
        self,
        scene: Scene,
        mount: Mount | None = None,
        conditions: Conditions | None = None,
        *,
        threads: int = 1,
    ) -> None:
        self.scene = scene
        self.mount = mount or Mount()
        self.conditions = conditions or Conditions()
        self.bands = _Bands(threads)
        """How the per-pixel kernels share a frame's rows out (``threads``: 1 or 2; the
        bytes are the same either way)."""
        self._balise_looks: dict[int, tuple[npt.NDArray[np.float64], list[int]]] = {}
        self._snow_masks: list[npt.NDArray[np.uint8]] = []
        self._sun: FloatArray | None = None

    def with_conditions(self, conditions: Conditions) -> Renderer:
        """The same scene and mount under other conditions (and the same threads)."""
        renderer = Renderer(self.scene, self.mount, conditions)
        renderer.bands = self.bands
        return renderer

    # --- the camera ------------------------------------------------------------------------

    def pose(self, distance_m: float) -> Pose:
        """The camera at the train's front, ``distance_m`` along the line."""
        centre, forward, right = (a[0] for a in self.scene.at(distance_m))
        up = np.cross(right, forward)
        pitch = math.radians(self.mount.pitch_deg)
        return Pose(
            position=centre + self.mount.height_m * up,
            right=right,
            up=math.sin(pitch) * forward + math.cos(pitch) * up,
            forward=math.cos(pitch) * forward - math.sin(pitch) * up,
        )

    # --- frames ----------------------------------------------------------------------------

    def rgb(
        self, camera: CameraModel, distance_m: float, view: View | None = None
    ) -> npt.NDArray[np.uint8]:
        """The colour frame ``(height, width, 3)``, rows top to bottom."""
        return self.render(camera, distance_m, view).pixels

    def render(self, camera: CameraModel, distance_m: float, view: View | None = None) -> Frame:
        """The colour frame and its labels."""
        view = view or View()
        c = self.conditions
        pose = self.pose(distance_m)
        light = self._light(view)
        objects = _Objects()
        faces = self._faces(
            pose, camera, distance_m, RANGE_M, objects, light.sun if light.shadows else None
        )
        k = _Prepared(faces, pose, camera)
        ids, inverse_z = k.rasterise(self.bands)
        height, width = camera.height, camera.width
        shadow = np.zeros((height, width), dtype=np.uint8)
        if light.shadows and faces.casters:
            raster.mask(k.shadow_quads(faces, light.sun), width, height, k.focal, NEAR_M, shadow)
        count = len(objects.kinds)
        pixels = np.zeros(count, dtype=np.int64)
        snowed = np.zeros(count, dtype=np.int64)
        boxes = np.tile(np.array([width, height, -1, -1], dtype=np.int64), (count, 1))
        radiance = np.empty((height, width, 3), dtype=np.float32)
        masks = np.stack(self._snow_masks) if self._snow_masks else np.zeros((1, 1, 1), np.uint8)
        lamp, lamp_axis = self._headlight(distance_m)
        extinction = c.extinction_per_m
        shaded = (
            ids,
            inverse_z,
            k.focal,
            k.albedo(faces, light),
            k.normals_world,
            k.emissive(faces, light),
            k.receives,
            k.objects,
            k.textures,
            *k.texture_frames(),
            masks,
            pose.position,
            k.axes,
            light.sun,
            light.direct,
            light.ambient,
            shadow,
            lamp,
            lamp_axis,
            light.lamp_candela,
            math.radians(HEADLIGHT_HALF_WIDTH_DEG),
            extinction,
            light.airlight,
            self._sky(pose, camera, light, extinction),
            radiance,
        )
        self.bands.shade(shaded, height, pixels, snowed, boxes)
        full = np.zeros(count, dtype=np.int64)
        if count:
            raster.coverage(k.quads, k.objects[1:], count, width, height, k.focal, NEAR_M, full)
        exposure_ms, gain = self._exposure(radiance)
        if c.motion_blur and view.speed_mps > 0.0:
            radiance = self._blurred(radiance, inverse_z, pose, camera, view, exposure_ms)
        self._precipitation(radiance, camera, view, light)
        out = np.empty((height, width, 3), dtype=np.uint8)
        per_electron = gain * 255.0 / c.full_well_e if c.noise else 0.0
        self.bands.run(
            raster.finish,
            height,
            radiance,
            exposure_ms * gain,
            per_electron,
            c.full_well_e / (255.0 * gain),
            c.read_noise_e,
            _key(c.seed, 6, round(view.elapsed_s * 1000.0)),
            raster.DEVIATES,
            out,
        )
        if c.jpeg_quality:
            buffer = io.BytesIO()
            Image.fromarray(out).save(buffer, "JPEG", quality=c.jpeg_quality)
            out = np.asarray(Image.open(io.BytesIO(buffer.getvalue())).convert("RGB"))
        labels = tuple(
            ObjectLabel(
                kind=objects.kinds[i],
                id=objects.ids[i],
                name=objects.names[i],
                box=tuple(int(b) for b in boxes[i]) if pixels[i] else (-1, -1, -1, -1),  # type: ignore[arg-type]
                pixels=int(pixels[i]),
                unoccluded_pixels=int(full[i]),
                snow_pixels=int(snowed[i]),
                distance_along_m=objects.along[i],
                distance_m=float(np.linalg.norm(objects.anchors[i] - pose.position)),
                transmittance=math.exp(
                    -extinction * float(np.linalg.norm(objects.anchors[i] - pose.position))
                ),
            )
            for i in range(count)
            if full[i] > 0
        )
        return Frame(out, labels, exposure_ms, gain)

    def depth(
        self, camera: CameraModel, distance_m: float, max_distance_m: float
    ) -> npt.NDArray[np.uint16]:
        """The depth frame ``(height, width, 3)``: class/id, distance scaled to
        ``max_distance_m`` over 0..65535, intensity (|cos| of the incidence) over 0..65535."""
        pose = self.pose(distance_m)
        faces = self._faces(pose, camera, distance_m, max_distance_m, _Objects(), None)
        k = _Prepared(faces, pose, camera)
        ids, inverse_z = k.rasterise(self.bands)
        frame = np.empty((camera.height, camera.width, 3), dtype=np.uint16)
        raster.depth_words(
            ids, inverse_z, k.normals_camera, k.codes, k.focal, max_distance_m, frame
        )
        return frame

    # --- light and camera --------------------------------------------------------------------

    def _light(self, view: View) -> _Light:
        c = self.conditions
        sky = np.array([SKY_HORIZON, SKY_ZENITH])
        airlight = HAZE if c.rain == 0 else RAIN_AIR
        if c.light == "fixed":
            return _Light(
                sun=SUN / np.linalg.norm(SUN),
                direct=np.full(3, 0.38),
                ambient=np.full(3, 0.62),
                shadows=False,
                lamp_candela=0.0,
                emissive=0.0,
                sky=sky,
                airlight=airlight.astype(np.float64),
            )
        lat, lon = self.scene.place
        sun = sun_position(
            latitude_deg=lat,
            longitude_deg=lon,
            day_of_year=c.date,
            local_time_s=view.clock_s,
            utc_offset_h=c.utc_offset_h,
        )
        day = daylight(sun.elevation_deg)
        low = min(max(1.0 - math.sin(math.radians(max(sun.elevation_deg, 0.0))) / 0.26, 0.0), 1.0)
        warm = np.array([1.0, 1.0 - 0.25 * low, 1.0 - 0.55 * low])
        cool = np.array([0.85, 0.92, 1.1]) if sun.elevation_deg < 0 else np.ones(3)
        overcast = 0.6 if c.rain > 0 or c.snowfall > 0 else 1.0
        brightness = day.ambient / AMBIENT_NOON
        sky[0] = SKY_HORIZON * (1.0 - 0.6 * low) + DUSK_HORIZON * 0.6 * low
        return _Light(
            sun=np.array(sun.direction()),
            direct=day.direct * warm * overcast * (1.0 if overcast == 1.0 else 0.3),
            ambient=day.ambient * cool * overcast,
            shadows=day.direct > 0.0 and overcast == 1.0,
            lamp_candela=HEADLIGHT_CANDELA / NOON_LUX if c.headlights else 0.0,
            emissive=1.0,
            sky=sky * brightness * overcast,
            airlight=airlight * brightness * overcast,
        )

    def _sky(
        self, pose: Pose, camera: CameraModel, light: _Light, extinction: float
    ) -> npt.NDArray[np.float32]:
        """The sky by row (the camera does not roll): zenith above, haze at the horizon, and
        the airlight the more the air holds beyond the clear haze."""
        rays = _rays(camera.width, camera.height, camera.fov_deg)[:, camera.width // 2]
        elevation = rays @ np.array([pose.right[2], pose.up[2], pose.forward[2]])
        blend = np.clip(elevation / 0.4, 0.0, 1.0)[:, None]
        horizon, zenith = light.sky
        sky = horizon * (1.0 - blend) + zenith * blend
        sky[elevation <= 0.0] = light.airlight
        thick = max(extinction - KOSCHMIEDER / DEFAULT_VISIBILITY_M, 0.0) * 1000.0
        if thick > 0.0:
            veil = 1.0 - math.exp(-thick)
            sky = sky * (1.0 - veil) + light.airlight * veil
        return np.ascontiguousarray(sky, dtype=np.float32)

    def _headlight(self, distance_m: float) -> tuple[FloatArray, FloatArray]:
        (centre,), (forward,), _ = self.scene.at(distance_m)
        dip = math.radians(0.5)
        axis = forward * math.cos(dip) - np.array([0.0, 0.0, 1.0]) * math.sin(dip)
        return centre + np.array([0.0, 0.0, HEADLIGHT_HEIGHT_M]), axis / np.linalg.norm(axis)

    def _exposure(self, radiance: npt.NDArray[np.float32]) -> tuple[float, float]:
        """Exposure [ms] and gain: as set, or metered (auto-exposure)."""
        c = self.conditions
        if not c.automatic:
            return c.exposure_ms, c.gain
        level = max(raster.metered(radiance), 1e-9)
        needed = EXPOSURE_TARGET / level  # exposure [ms] x gain
        exposure = min(needed, c.max_exposure_ms)
        gain = min(max(needed / exposure, 1.0), c.max_gain)
        return exposure, gain

    def _blurred(
        self,
        radiance: npt.NDArray[np.float32],
        inverse_z: npt.NDArray[np.float64],
        pose: Pose,
        camera: CameraModel,
        view: View,
        exposure_ms: float,
    ) -> npt.NDArray[np.float32]:
        # the train moves along the track: in the camera's frame, up by the mount's pitch
        along = np.array(
            [
                0.0,
                math.sin(math.radians(self.mount.pitch_deg)),
                math.cos(math.radians(self.mount.pitch_deg)),
            ]
        )
        focal = camera.focal_px
        focus_u = camera.width / 2.0 + focal * along[0] / along[2]
        focus_v = camera.height / 2.0 - focal * along[1] / along[2]
        per_inverse_z = view.speed_mps * along[2] * exposure_ms / 1000.0
        out = np.empty_like(radiance)
        raster.motion_blur(radiance, inverse_z, focus_u, focus_v, per_inverse_z, out)
        return out

    def _precipitation(
        self,
        radiance: npt.NDArray[np.float32],
        camera: CameraModel,
        view: View,
        light: _Light,
    ) -> None:
        """Rain streaks and snowflakes in front of the camera, drawn anew for each frame."""
        c = self.conditions
        scale = camera.width * camera.height / 480_000.0
        size = camera.height / 600.0
        level = light.ambient + light.direct * 0.5
        if c.rain > 0.0:
            rng = np.random.default_rng([c.seed, 7, round(view.elapsed_s * 1000.0)])
            n = round(400 * c.rain**0.5 * scale)
            u = rng.uniform(0, camera.width, n)
            v = rng.uniform(0, camera.height, n)
            length = rng.uniform(8, 40, n) * size
            slant = rng.uniform(-0.15, 0.15, n)
            segments = np.column_stack(
                [
                    u,
                    v,
                    u + length * np.sin(slant),
                    v + length * np.cos(slant),
                    rng.uniform(0.08, 0.25, n),
                ]
            )
            colour = np.minimum(light.airlight * 1.3, 255.0)
            raster.streaks(radiance, segments, colour.astype(np.float64))
        if c.snowfall > 0.0:
            rng = np.random.default_rng([c.seed, 8, round(view.elapsed_s * 1000.0)])
            n = round(600 * c.snowfall**0.7 * scale)
            discs = np.column_stack(
                [
                    rng.uniform(0, camera.width, n),
                    rng.uniform(0, camera.height, n),
                    rng.uniform(0.6, 2.5, n) * size,
                    rng.uniform(0.5, 0.9, n),
                ]
            )
            colour = np.minimum(np.array(SNOW) * level, 255.0)
            raster.flakes(radiance, discs, colour.astype(np.float64))

    # --- geometry --------------------------------------------------------------------------

    def _faces(
        self,
        pose: Pose,
        camera: CameraModel,
        distance_m: float,
        reach_m: float,
        objects: _Objects,
        sun: FloatArray | None,
    ) -> _Faces:
        """The quads in view; with ``sun`` (towards it) the shadow casters too."""
        faces = _Faces()
        self._sun = sun
        self._terrain(faces, pose, camera, distance_m, reach_m)
        ahead = min(self.scene.length, distance_m + reach_m)
        bounds = _segment_bounds(distance_m, ahead)
        if len(bounds) >= 2:
            self._track(faces, bounds, distance_m)
            self._balises(faces, bounds, distance_m, ahead, objects)
            self._platforms(faces, bounds, distance_m, ahead, objects)
            self._signals(faces, bounds, distance_m, ahead, objects)
            if self.conditions.trees_per_km > 0:
                self._trees(faces, pose, bounds, distance_m, ahead, sun)
            if self.conditions.leaves > 0:
                self._leaves(faces, bounds, distance_m, min(ahead, distance_m + LEAVES_RANGE_M))
        return faces

    def _ground(self, colour: tuple[int, int, int], cover: float, wet: float) -> FloatArray:
        """A ground colour under snow (fraction ``cover``) and wet (darker)."""
        base = np.asarray(colour, dtype=np.float64) * (1.0 - 0.35 * wet)
        return base * (1.0 - cover) + np.asarray(SNOW, dtype=np.float64) * cover

    def _terrain(
        self, faces: _Faces, pose: Pose, camera: CameraModel, distance_m: float, reach_m: float
    ) -> None:
        """A fan of quads around the camera at the track's height ``TERRAIN_M`` below the
        rails at the same distance ahead (a surface of revolution following the gradient)."""
        radii = np.array([0.0, 1, 2, 3, 5, 8, 12, 18, 27, 40, 60, 90, 135, 200, 300, 450, 700])
        radii = np.append(radii[radii < reach_m], reach_m)
        heading = math.atan2(pose.forward[0], pose.forward[1])
        half = math.degrees(math.atan(camera.width / 2.0 / camera.focal_px)) + 12.0
        angles = heading + np.radians(np.linspace(-half, half, 13))
        heights = self.scene.at(distance_m + radii)[0][:, 2] + TERRAIN_M
        ground = pose.position[:2]
        x = ground[0] + radii[:, None] * np.sin(angles)[None, :]
        y = ground[1] + radii[:, None] * np.cos(angles)[None, :]
        z = np.broadcast_to(heights[:, None], x.shape)
        grid = np.stack([x, y, z], axis=-1)
        quads = np.stack(
            [grid[:-1, :-1], grid[:-1, 1:], grid[1:, 1:], grid[1:, :-1]], axis=2
        ).reshape(-1, 4, 3)
        ring = np.repeat(radii[:-1], len(angles) - 1)
        c = self.conditions
        grass = self._ground(GRASS, c.snow, _wetness(c))
        faces.add(quads, grass, code(TERRAIN, 0), group=0, distance=ring, layer=0)

    def _track(self, faces: _Faces, bounds: FloatArray, camera_m: float) -> None:
        centre, _, right = self.scene.at(bounds)
        section = self.scene.section_at(bounds[:-1]) + 1
        near = bounds[:-1]
        rel = near - camera_m
        c = self.conditions
        cover, wet = c.snow, _wetness(c)

        def strip(l0: float, h0: float, l1: float, h1: float) -> FloatArray:
            return _strip(centre, right, l0, h0, l1, h1)

        terrain = code(TERRAIN, 0)
        for side in (-1.0, 1.0):
            quads = strip(
                side * BALLAST_HALF_WIDTH_M,
                BALLAST_TOP_M,
                side * TERRAIN_HALF_WIDTH_M,
                TERRAIN_M,
            )
            shoulder = self._ground(SHOULDER, cover * 0.9, wet)
            faces.add(quads, shoulder, terrain, group=1, distance=rel, layer=0)
        bed = np.where(
            (rel < SLEEPER_RANGE_M)[:, None],
            self._ground(BALLAST, cover * 0.9, wet),
            self._ground(BALLAST_FAR, cover * 0.9, wet),
        )
        quads = strip(-BALLAST_HALF_WIDTH_M, BALLAST_TOP_M, BALLAST_HALF_WIDTH_M, BALLAST_TOP_M)
        faces.add(quads, bed, terrain, group=1, distance=rel, layer=1)

        # sleepers: fixed on the line every SLEEPER_SPACING_M, filed under their segment
        first = math.ceil((camera_m + 1.0) / SLEEPER_SPACING_M)
        last = math.floor(min(camera_m + SLEEPER_RANGE_M, bounds[-1]) / SLEEPER_SPACING_M)
        if last >= first:
            at = np.arange(first, last + 1) * SLEEPER_SPACING_M
            half = SLEEPER_WIDTH_M / 2.0
            c0, _, r0 = self.scene.at(at - half)
            c1, _, r1 = self.scene.at(at + half)
            h = np.array([0.0, 0.0, -RAIL_HEIGHT_M])
            ends = SLEEPER_LENGTH_M / 2.0
            quads = np.stack(
                [c0 - ends * r0 + h, c0 + ends * r0 + h, c1 + ends * r1 + h, c1 - ends * r1 + h],
                axis=1,
            )
            seg = _segment_of(bounds, at)
            ids = self.scene.section_at(at) + 1
            codes = (TRACK << ID_BITS) | (ids & 0x1FFF)
            sleeper = self._ground(SLEEPER, cover * 0.7, wet)
            faces.add(quads, sleeper, codes, group=1, distance=bounds[seg] - camera_m, layer=2)

        rail_codes = (TRACK << ID_BITS) | (section & 0x1FFF)
        inner = GAUGE_M / 2.0 - RAIL_HEAD_M / 2.0
        outer = GAUGE_M / 2.0 + RAIL_HEAD_M / 2.0
        for side in (-1.0, 1.0):
            quads = strip(side * inner, 0.0, side * inner, -RAIL_HEIGHT_M)
            rail_side = self._ground(RAIL_SIDE, cover * 0.3, 0.0)
            faces.add(quads, rail_side, rail_codes, group=1, distance=rel, layer=3)
            quads = strip(side * inner, 0.0, side * outer, 0.0)
            faces.add(quads, RAIL_TOP, rail_codes, group=1, distance=rel, layer=4)

    def _balise_look(self, balise_code: int) -> tuple[npt.NDArray[np.float64], list[int]]:
        """A balise's colours (top, side) after dirt and rain, and the snow pattern of each of
        its five faces (-1: no snow), drawn from the seed and its code: the same balise looks
        the same all run."""
        cached = self._balise_looks.get(balise_code)
        if cached is not None:
            return cached
        c = self.conditions
        rng = np.random.default_rng([c.seed, 4, balise_code & 0xFFFFFFFF])
        level = min(c.dirt * rng.uniform(0.5, 1.5), 1.0)
        colours = np.array([BALISE_TOP, BALISE_SIDE], dtype=np.float64)
        colours = colours * (1.0 - level) + np.asarray(DIRT) * level
        colours *= 1.0 - 0.1 * _wetness(c)
        textures = [-1] * 5
        if c.snow > 0.0:
            for face in range(5):
                self._snow_masks.append(_snow_pattern(rng, c.snow))
                textures[face] = len(self._snow_masks) - 1
        look = (colours, textures)
        self._balise_looks[balise_code] = look
        return look

    def _balises(
        self, faces: _Faces, bounds: FloatArray, camera_m: float, ahead: float, objects: _Objects
    ) -> None:
        half = BALISE_ALONG_M / 2.0
        across = BALISE_ACROSS_M / 2.0
        low, high = -RAIL_HEIGHT_M, -RAIL_HEIGHT_M + BALISE_HEIGHT_M
        places = np.array([b.distance_m for b in self.scene.balises])
        chosen = np.flatnonzero((places > camera_m + NEAR_M + half) & (places < ahead - half))
        if not len(chosen):
            return
        d = places[chosen]
        centres, _, rights = self.scene.at(np.concatenate([d - half, d + half]))
        n = len(d)
        segments = bounds[_segment_of(bounds, d)] - camera_m
        for i, index in enumerate(chosen.tolist()):
            balise = self.scene.balises[index]
            ends = ((centres[i], rights[i]), (centres[n + i], rights[n + i]))
            box = {
                (a, s, z): c + s * across * r + np.array([0.0, 0.0, z])
                for a, (c, r) in enumerate(ends)
                for s in (-1.0, 1.0)
                for z in (low, high)
            }
            quads = [
                [box[1, -1, low], box[1, 1, low], box[1, 1, high], box[1, -1, high]],  # far
                [box[0, -1, low], box[1, -1, low], box[1, -1, high], box[0, -1, high]],  # left
                [box[0, 1, low], box[1, 1, low], box[1, 1, high], box[0, 1, high]],  # right
                [box[0, -1, low], box[0, 1, low], box[0, 1, high], box[0, -1, high]],  # near
                [box[0, -1, high], box[0, 1, high], box[1, 1, high], box[1, -1, high]],  # top
            ]
            (top, side), texture = self._balise_look(balise.code)
            centre = (ends[0][0] + ends[1][0]) / 2.0
            obj = objects.add(
                "balise",
                balise.code,
                balise.name,
                float(d[i]) - camera_m,
                centre + np.array([0.0, 0.0, high]),
            )
            faces.add(
                np.array(quads),
                np.array([side] * 4 + [top]),
                code(BALISE, balise.code),
                group=1,
                distance=float(segments[i]),
                layer=5 + np.arange(5) / 10.0,
                obj=obj,
                texture=np.array(texture),
            )

    def _platforms(
        self, faces: _Faces, bounds: FloatArray, camera_m: float, ahead: float, objects: _Objects
    ) -> None:
        c = self.conditions
        for platform in self.scene.platforms:
            start = max(platform.start_m, camera_m + NEAR_M)
            end = min(platform.end_m, ahead)
            if end <= start:
                continue
            inside = bounds[(bounds > start) & (bounds < end)]
            cuts = np.concatenate([[start], inside, [end]])
            centre, _, right = self.scene.at(cuts)
            side, top = platform.side, platform.height_m
            rel = _segment_start(bounds, cuts[:-1]) - camera_m
            ident = code(UNKNOWN, platform.index)
            edge = side * PLATFORM_EDGE_M
            anchor = centre[0] + edge * right[0] + np.array([0.0, 0.0, top])
            obj = objects.add(
                "platform_edge", platform.index, platform.name, start - camera_m, anchor
            )
            back = side * (PLATFORM_EDGE_M + PLATFORM_DEPTH_M)
            line0, line1 = side * (PLATFORM_EDGE_M + 0.25), side * (PLATFORM_EDGE_M + 0.33)
            wet = _wetness(c) * 0.6
            for layer, colour, quads in (
                (6.0, PLATFORM_EDGE, _strip(centre, right, edge, BALLAST_TOP_M, edge, top)),
                (6.1, PLATFORM_TOP, _strip(centre, right, edge, top, back, top)),
                (6.2, PLATFORM_LINE, _strip(centre, right, line0, top, line1, top)),
            ):
                look = self._ground(colour, c.snow if layer > 6.0 else 0.0, wet)
                faces.add(
                    quads, look, ident, group=1, distance=rel, layer=layer, kind=CASTER, obj=obj
                )
                if layer < 6.2:
                    self._cast(faces, quads, cuts[:-1])
            if c.platform_roofs:
                roof = _strip(
                    centre, right, edge + side * 0.6, top + ROOF_HEIGHT_M, back, top + ROOF_HEIGHT_M
                )
                faces.add(
                    roof, ROOF, code(TERRAIN, 0), group=1, distance=rel, layer=6.3, kind=CASTER
                )
                self._cast(faces, roof, cuts[:-1])

    def _signals(
        self, faces: _Faces, bounds: FloatArray, camera_m: float, ahead: float, objects: _Objects
    ) -> None:
        places = np.array([g.distance_m for g in self.scene.signals])
        chosen = np.flatnonzero((places > camera_m + 2.0) & (places < ahead))
        if not len(chosen):
            return
        centres, _, rights = self.scene.at(places[chosen])
        for i, index in enumerate(chosen.tolist()):
            signal = self.scene.signals[index]
            d, c, r = signal.distance_m, centres[i], rights[i]
            ident = code(SIGNAL, signal.index)
            lateral = signal.side * SIGNAL_OFFSET_M
            quads = np.array(
                [
                    _panel(c, r, lateral, 0.08, TERRAIN_M, 4.2),
                    _panel(c, r, lateral, 0.3, 4.0, 5.4),
                    _panel(c, r, lateral, 0.12, 4.9, 5.2),
                ]
            )
            colours = np.array([MAST, SIGNAL_HEAD, LAMP], dtype=np.float64)
            seg = _segment_of(bounds, np.array([d]))[0]
            head = c + lateral * r + np.array([0.0, 0.0, 4.7])
            obj = objects.add("signal", signal.index, signal.name, d - camera_m, head)
            for i, kind in enumerate((CASTER, CASTER, LAMP_FACE)):
                faces.add(
                    quads[i : i + 1],
                    colours[i],
                    ident,
                    group=1,
                    distance=float(bounds[seg]) - camera_m,
                    layer=7 + i / 10.0,
                    kind=kind,
                    obj=obj,
                )
            self._cast(faces, quads[:2], d)

    def _trees(
        self,
        faces: _Faces,
        pose: Pose,
        bounds: FloatArray,
        camera_m: float,
        ahead: float,
        sun: FloatArray | None,
    ) -> None:
        """Trees from the seed, per 100 m of line: a trunk and a crown, each a panel facing
        the camera (and, for their shadows, facing the sun)."""
        c = self.conditions
        cells = range(int(camera_m // TREE_CELL_M), int(ahead // TREE_CELL_M) + 1)
        rows = [row for cell in cells for row in _trees_of(c.seed, c.trees_per_km, cell)]
        table = np.array(rows, dtype=np.float64).reshape(-1, 5)
        table = table[(table[:, 0] > camera_m + 3.0) & (table[:, 0] < ahead)]
        if not len(table):
            return
        along, lateral, radius, trunk, tint = table.T
        centre, _, right = self.scene.at(along)
        foot = centre + lateral[:, None] * right + np.array([0.0, 0.0, TERRAIN_M])
        towards = pose.position[:2] - foot[:, :2]
        facing = np.column_stack([-towards[:, 1], towards[:, 0], np.zeros(len(foot))])
        facing /= np.maximum(np.linalg.norm(facing, axis=1, keepdims=True), 1e-9)
        stems, crowns = _tree_quads(foot, facing, radius, trunk)
        distance = bounds[_segment_of(bounds, along)] - camera_m
        crown = np.asarray(CROWN, dtype=np.float64) * tint[:, None]
        crown = crown * (1.0 - c.snow * 0.5) + np.asarray(SNOW) * c.snow * 0.5
        terrain = code(TERRAIN, 0)
        faces.add(stems, TRUNK, terrain, group=1, distance=distance, layer=8, kind=CASTER)
        faces.add(crowns, crown, terrain, group=1, distance=distance, layer=8.1, kind=CASTER)
        if sun is not None and math.hypot(sun[0], sun[1]) > 1e-9:
            sideways = np.array([-sun[1], sun[0], 0.0]) / math.hypot(sun[0], sun[1])
            across = np.broadcast_to(sideways, foot.shape)
            stems, crowns = _tree_quads(foot, across, radius, trunk)
            self._cast(faces, np.concatenate([stems, crowns]), np.concatenate([along, along]))

    def _leaves(self, faces: _Faces, bounds: FloatArray, camera_m: float, ahead: float) -> None:
        """Leaves (and other yellow things) on and beside the ballast, per 10 m of line."""
        c = self.conditions
        first, last = int(camera_m // LEAF_CELL_M), int(ahead // LEAF_CELL_M)
        rows = [_leaves_of(c.seed, c.leaves, cell) for cell in range(first, last + 1)]
        table = np.concatenate(rows) if rows else np.zeros((0, 5))
        table = table[(table[:, 0] > camera_m + 1.0) & (table[:, 0] < ahead)]
        if not len(table):
            return
        along, lateral, size, angle, tone = table.T
        centre, forward, right = self.scene.at(along)
        lift = (
            np.interp(
                np.abs(lateral),
                [0.0, 1.3, 1.3001, BALLAST_HALF_WIDTH_M, TERRAIN_HALF_WIDTH_M, 99.0],
                [
                    -RAIL_HEIGHT_M,
                    -RAIL_HEIGHT_M,
                    BALLAST_TOP_M,
                    BALLAST_TOP_M,
                    TERRAIN_M,
                    TERRAIN_M,
                ],
            )
            + 0.006
        )
        middle = centre + lateral[:, None] * right + lift[:, None] * np.array([0.0, 0.0, 1.0])
        a = forward * np.cos(angle)[:, None] + right * np.sin(angle)[:, None]
        b = -forward * np.sin(angle)[:, None] + right * np.cos(angle)[:, None]
        h = (size / 2.0)[:, None]
        quads = np.stack(
            [
                middle - h * a - h * b,
                middle + h * a - h * b,
                middle + h * a + h * b,
                middle - h * a + h * b,
            ],
            axis=1,
        )
        colours = LEAF_COLOURS[tone.astype(int)] * (1.0 - 0.35 * _wetness(c))
        seg = _segment_of(bounds, along)
        faces.add(
            quads, colours, code(TERRAIN, 0), group=1, distance=bounds[seg] - camera_m, layer=4.5
        )

    def _cast(self, faces: _Faces, quads: FloatArray, along: float | FloatArray) -> None:
        """Register ``quads`` as shadow casters onto the ground's level where they stand
        (``along`` the line): the top of the rails there plus ``SHADOW_LEVEL_M``."""
        if self._sun is None:
            return
        quads = np.asarray(quads)
        level = self.scene.at(np.broadcast_to(along, (len(quads),)))[0][:, 2] + SHADOW_LEVEL_M
        rows = np.zeros((len(quads), 5, 3))
        rows[:, :4] = quads
        rows[:, 4, 2] = level
        faces.casters.append(rows)


def _wetness(c: Conditions) -> float:
    return min(c.rain / 2.0, 1.0)


def _snow_pattern(rng: np.random.Generator, cover: float) -> npt.NDArray[np.uint8]:
    """Which 4 cm cells of a balise face lie under snow: exactly ``cover`` of them, in
    drifts (a smoothed random field above its quantile)."""
    field_ = rng.standard_normal((SNOW_CELLS[0] + 4, SNOW_CELLS[1] + 4))
    for _ in range(2):
        field_ = (field_[:-2] + field_[1:-1] + field_[2:]) / 3.0
        field_ = (field_[:, :-2] + field_[:, 1:-1] + field_[:, 2:]) / 3.0
    order = np.argsort(-field_, axis=None, kind="stable")
    pattern = np.zeros(field_.size, dtype=np.uint8)
    pattern[order[: round(cover * field_.size)]] = 1
    return pattern.reshape(field_.shape)


def _key(*parts: int) -> np.uint64:
    """A 64-bit seed of integers (the noise kernel's key)."""
    state = np.random.SeedSequence([p & 0xFFFFFFFFFFFFFFFF for p in parts]).generate_state(
        1, np.uint64
    )
    return np.uint64(state[0])


@lru_cache(maxsize=256)
def _trees_of(
    seed: int, per_km: float, cell: int
) -> tuple[tuple[float, float, float, float, float], ...]:
    """Trees of a 100 m cell of the line: (along, lateral, crown radius, trunk height, tint)."""
    rng = np.random.default_rng([seed, 1, cell & 0xFFFFFFFF])
    n = rng.poisson(per_km * TREE_CELL_M / 1000.0)
    along = cell * TREE_CELL_M + rng.uniform(0, TREE_CELL_M, n)
    lateral = rng.choice([-1.0, 1.0], n) * rng.uniform(4.5, 18.0, n)
    return tuple(
        zip(
            along.tolist(),
            lateral.tolist(),
            rng.uniform(1.2, 2.8, n).tolist(),
            rng.uniform(1.5, 3.5, n).tolist(),
            rng.uniform(0.8, 1.2, n).tolist(),
            strict=True,
        )
    )


@lru_cache(maxsize=1024)
def _leaves_of(seed: int, per_m2: float, cell: int) -> npt.NDArray[np.float64]:
    """Leaf clumps of a 10 m cell: rows (along, lateral, size, angle, colour index)."""
    rng = np.random.default_rng([seed, 2, cell & 0xFFFFFFFF])
    n = rng.poisson(per_m2 * LEAF_CELL_M * 2 * LEAVES_HALF_WIDTH_M)
    return np.column_stack(
        [
            cell * LEAF_CELL_M + rng.uniform(0, LEAF_CELL_M, n),
            rng.uniform(-LEAVES_HALF_WIDTH_M, LEAVES_HALF_WIDTH_M, n),
            rng.uniform(0.08, 0.3, n),
            rng.uniform(0, math.pi, n),
            rng.integers(0, len(LEAF_COLOURS), n),
        ]
    ).reshape(n, 5)


def _tree_quads(
    foot: FloatArray, across: FloatArray, radius: FloatArray, trunk: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Trunks (0.3 m wide) and diamond crowns ``(n, 4, 3)``, upright, spanning ``across``."""
    up = np.array([0.0, 0.0, 1.0])
    side = 0.15 * across
    top = trunk[:, None] * up
    stems = np.stack([foot - side, foot + side, foot + side + top, foot - side + top], axis=1)
    middle = foot + (trunk + radius)[:, None] * up
    r = radius[:, None]
    crowns = np.stack(
        [middle - r * up, middle + r * across, middle + r * up, middle - r * across], axis=1
    )
    return stems, crowns


class _Bands:
    """A frame's rows shared out between the calling thread and, with two threads, one helper
    thread. The per-pixel kernels (rasterise, shade, finish) compute a pixel from its own row
    alone and release the GIL, so two bands run side by side and give the bytes the whole
    frame gives. Where the rows split follows where the time went the frame before (a row of
    sky costs less than a row of track): that moves the cost between the threads, never a
    byte."""

    def __init__(self, threads: int) -> None:
        if threads not in (1, 2):
            raise ValueError(f"render threads must be 1 or 2, not {threads}")
        self._helper = (
            ThreadPoolExecutor(1, thread_name_prefix="render-band") if threads == 2 else None
        )
        self._split: dict[str, float] = {}
        """Each kernel's share of the rows the calling thread takes (the top ones)."""

    def run(self, kernel: Callable[..., None], height: int, *args: Any) -> None:
        """``kernel(*args, row_begin, row_end)`` over rows 0 to ``height``."""
        self._two(kernel, height, args, args)

    def shade(
        self,
        args: tuple[Any, ...],
        height: int,
        pixels: npt.NDArray[np.int64],
        snowed: npt.NDArray[np.int64],
        boxes: npt.NDArray[np.int64],
    ) -> None:
        """``raster.shade`` over rows 0 to ``height``; each band counts its objects' pixels
        and spans their boxes apart, and the counts are summed and the boxes joined after."""
        if self._helper is None:
            self._two(raster.shade, height, (*args, pixels, snowed, boxes), ())
            return
        counted = (np.zeros_like(pixels), np.zeros_like(snowed), boxes.copy())
        self._two(raster.shade, height, (*args, pixels, snowed, boxes), (*args, *counted))
        pixels += counted[0]
        snowed += counted[1]
        np.minimum(boxes[:, :2], counted[2][:, :2], out=boxes[:, :2])
        np.maximum(boxes[:, 2:], counted[2][:, 2:], out=boxes[:, 2:])

    def _two(
        self,
        kernel: Callable[..., None],
        height: int,
        mine: tuple[Any, ...],
        theirs: tuple[Any, ...],
    ) -> None:
        if self._helper is None:
            kernel(*mine, 0, height)
            return
        name = getattr(kernel, "__name__", "")
        share = self._split.get(name, 0.5)
        split = min(max(round(height * share), 1), height - 1)
        began = time.perf_counter()
        other = self._helper.submit(_timed, kernel, (*theirs, split, height))
        kernel(*mine, 0, split)
        took = time.perf_counter() - began
        their_took = other.result()
        # the rows each thread would take to finish together, at this frame's cost per row
        top, bottom = took / split, their_took / (height - split)
        if top > 0.0 and bottom > 0.0:
            balanced = bottom / (top + bottom)
            self._split[name] = min(max((share + balanced) / 2.0, 0.1), 0.9)


def _timed(kernel: Callable[..., None], args: tuple[Any, ...]) -> float:
    began = time.perf_counter()
    kernel(*args)
    return time.perf_counter() - began


class _Prepared:
    """The faces in drawing order, in camera coordinates, as the kernels take them."""

    def __init__(self, faces: _Faces, pose: Pose, camera: CameraModel) -> None:
        self.pose = pose
        self.camera = camera
        self.focal = camera.focal_px
        order = np.concatenate(faces.order)
        rank = np.lexsort((order[:, 2], -order[:, 1], order[:, 0]))
        world = np.concatenate(faces.corners)[rank]
        self.world = world
        self.quads = np.ascontiguousarray(pose.to_camera(world))
        self.background = np.ascontiguousarray(order[rank, 0] == 0)
        self.rank = rank
        kinds = np.concatenate(faces.kinds)[rank]
        # per id (row 0: nothing)
        self.codes = _with_none(np.concatenate(faces.codes)[rank].astype(np.uint16))
        self.objects = _with_none(np.concatenate(faces.objects)[rank].astype(np.int64), -1)
        self.textures = _with_none(np.concatenate(faces.textures)[rank].astype(np.int64), -1)
        self.kinds = kinds
        self.receives = _with_none((kinds == GROUND).astype(np.uint8))
        normals = np.cross(world[:, 2] - world[:, 0], world[:, 3] - world[:, 1])
        norm = np.linalg.norm(normals, axis=1)
        normals = normals / np.maximum(norm, 1e-300)[:, None]
        towards = np.einsum("ij,ij->i", normals, world.mean(axis=1) - pose.position) > 0.0
        normals[towards] *= -1.0  # the normal must point to the camera
        self.normals_world = _with_none(normals)
        self.normals_camera = _with_none(
            np.stack([normals @ pose.right, normals @ pose.up, normals @ pose.forward], axis=-1)
        )
        self.axes = np.stack([pose.right, pose.up, pose.forward])
        self._colours = np.concatenate(faces.colours)[rank]

    def rasterise(self, bands: _Bands) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float64]]:
        ids = np.empty((self.camera.height, self.camera.width), dtype=np.int32)
        inverse_z = np.empty((self.camera.height, self.camera.width), dtype=np.float64)
        bands.run(
            raster.rasterise,
            self.camera.height,
            self.quads,
            self.background,
            self.camera.width,
            self.camera.height,
            self.focal,
            NEAR_M,
            ids,
            inverse_z,
        )
        return ids, inverse_z

    def albedo(self, faces: _Faces, light: _Light) -> FloatArray:
        return _with_none(self._colours)

    def emissive(self, faces: _Faces, light: _Light) -> FloatArray:
        glow = np.zeros_like(self._colours)
        lamps = self.kinds == LAMP_FACE
        glow[lamps] = self._colours[lamps] * 0.5 * light.emissive
        return _with_none(glow)

    def texture_frames(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Per face: origin and the u, v axes (scaled to 1 over the face) of a textured face
        (its first corner, along its first and last edges)."""
        origin = self.world[:, 0]
        u = self.world[:, 1] - origin
        v = self.world[:, 3] - origin
        u = u / np.maximum(np.sum(u * u, axis=1), 1e-300)[:, None]
        v = v / np.maximum(np.sum(v * v, axis=1), 1e-300)[:, None]
        return _with_none(origin), _with_none(u), _with_none(v)

    def shadow_quads(self, faces: _Faces, sun: FloatArray) -> FloatArray:
        """The casters' quads laid along the sun onto their ground level, in camera
        coordinates."""
        casters = np.concatenate(faces.casters)
        quads, level = casters[:, :4], casters[:, 4, 2]
        lift = (quads[:, :, 2] - level[:, None]) / max(float(sun[2]), 1e-3)
        ground = quads - lift[:, :, None] * sun
        return np.ascontiguousarray(self.pose.to_camera(ground))


def _with_none(values: npt.NDArray[Any], none: float = 0) -> npt.NDArray[Any]:
    """``values`` with a row for id 0 (nothing) in front."""
    head = np.full((1, *values.shape[1:]), none, dtype=values.dtype)
    return np.ascontiguousarray(np.concatenate([head, values]))


def _strip(
    centre: FloatArray, right: FloatArray, l0: float, h0: float, l1: float, h1: float
) -> FloatArray:
    """Quads between consecutive cross-sections: from lateral ``l0`` at height ``h0`` to
    ``l1`` at ``h1`` (metres right of, and above, the top of the rails)."""
    up = np.array([0.0, 0.0, 1.0])
    a0 = centre[:-1] + l0 * right[:-1] + h0 * up
    a1 = centre[:-1] + l1 * right[:-1] + h1 * up
    b1 = centre[1:] + l1 * right[1:] + h1 * up
    b0 = centre[1:] + l0 * right[1:] + h0 * up
    return np.stack([a0, a1, b1, b0], axis=1)


def _panel(
    centre: FloatArray, right: FloatArray, lateral: float, half: float, bottom: float, top: float
) -> FloatArray:
    """An upright rectangle across the track, ``lateral`` +- ``half`` to the right."""
    up = np.array([0.0, 0.0, 1.0])
    left, far = lateral - half, lateral + half
    return np.array(
        [
            centre + left * right + bottom * up,
            centre + far * right + bottom * up,
            centre + far * right + top * up,
            centre + left * right + top * up,
        ]
    )


def _segment_bounds(start: float, end: float) -> FloatArray:
    """Along-line cuts of the track from ``start`` to ``end``: fine near the camera, coarse
    far away (0.6 m to 40 m ahead, 1.2 m to 80 m, 3 m to 200 m, 12 m beyond)."""
    parts: list[npt.ArrayLike] = [
        np.arange(start, start + 40.0, 0.6),
        np.arange(start + 40.0, start + 80.0, 1.2),
        np.arange(start + 80.0, start + 200.0, 3.0),
        np.arange(start + 200.0, end, 12.0),
        [end],
    ]
    cuts = np.concatenate([np.atleast_1d(np.asarray(p, dtype=np.float64)) for p in parts])
    return np.asarray(cuts[cuts <= end], dtype=np.float64)


def _segment_of(bounds: FloatArray, distances: FloatArray) -> npt.NDArray[np.int64]:
    """Index of the segment ``[bounds[i], bounds[i + 1])`` holding each distance."""
    return np.clip(np.searchsorted(bounds, distances, side="right") - 1, 0, len(bounds) - 2)


def _segment_start(bounds: FloatArray, distances: FloatArray) -> FloatArray:
    return np.asarray(bounds[_segment_of(bounds, distances)], dtype=np.float64)


@lru_cache(maxsize=8)
def _rays(width: int, height: int, fov_deg: float) -> npt.NDArray[np.float32]:
    """Unit ray of every pixel centre ``(height, width, 3)`` in camera coordinates."""
    focal = height / 2.0 / math.tan(math.radians(fov_deg) / 2.0)
    cols = (np.arange(width) - (width / 2.0 - 0.5)) / focal
    rows = -(np.arange(height) - (height / 2.0 - 0.5)) / focal
    x, y = np.meshgrid(cols, rows)
    rays = np.stack([x, y, np.ones_like(x)], axis=-1)
    unit = (rays / np.linalg.norm(rays, axis=-1, keepdims=True)).astype(np.float32)
    unit.setflags(write=False)
    return unit
