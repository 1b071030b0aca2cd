"""Frames of the mock's cameras: the scene seen from the train's cab, rasterised on the CPU.

What is drawn (``scene``): the terrain, the ballast bed, sleepers (up to ``SLEEPER_RANGE_M``)
and the two rails along the line's B-spline (curves and gradients included), balises as yellow
boxes between the rails, signals beside the track and platform edges, each a flat-shaded
planar quad.

How: every quad is projected with a pinhole camera and filled into an object-id buffer with
Pillow's polygon fill (``ImageDraw.polygon``, C code), far to near (the painter's algorithm:
the terrain first, then the track bed and what stands on it, segment by segment from the
farthest). Per pixel, numpy then intersects the pixel's ray with the plane of the quad that
covers it: the exact distance, hence the haze of the colour frame and the distance, class and
intensity of the depth frame. Pillow and numpy install from wheels everywhere and need no GPU,
no display and no OpenGL; the same state gives the same bytes.

The camera (``Mount``) rides at the front of the train, ``height_m`` above the top of the
rails, looking along the track and pitched down by ``pitch_deg``; ``fov`` of a sensor is its
vertical field of view, pixels are square. Pixel centres follow a GPU's rasteriser: the
optical axis passes between the two middle columns and rows (OpenCV intrinsics
cx = width / 2 - 0.5, cy = height / 2 - 0.5).

Depth frames carry OpenRails' classes (``ObjectClassifiers`` of its Python client):
TERRAIN 1 (terrain and ballast), TRACK 2 (rails and sleepers; id = the route section's index
+ 1), SIGNAL 5 (id = the signal's number), UNKNOWN 0 for platforms (id = the platform edge's
number, never 0) and BALISE = CUSTOM1 6 (id = the balise's code, modulo 8192). A pixel with
nothing within ``max_distance`` (the sky) is all zeros.

Limits: no z-buffer (a hill does not hide the track behind it; the terrain is a fan around the
camera at the track's height), no textures, no other trains, no lights or weather.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt
from PIL import Image, ImageDraw

from .scene import Scene

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
RANGE_M = 600.0
"""How far colour frames show the track."""
NEAR_M = 0.25
DEPTH_SUPERSAMPLING = 3
"""Depth frames are rasterised this many times finer (their distances are exact per pixel)."""
HAZE_M = 3000.0

SKY_ZENITH = np.array([96.0, 140.0, 200.0])
SKY_HORIZON = np.array([196.0, 212.0, 228.0])
HAZE = np.array([190.0, 200.0, 210.0])
SUN = np.array([-0.45, -0.55, 0.70])
"""Towards the sun (world frame: east, north, up), unnormalised."""

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


@dataclass
class _Faces:
    """Quads in world coordinates, each with a colour, a depth code and a drawing order."""

    corners: list[FloatArray]
    colours: list[npt.NDArray[np.uint8]]
    codes: list[npt.NDArray[np.int64]]
    order: list[FloatArray]
    """Rows (group, distance, layer): drawn by group, then farthest first, then by layer."""

    def add(
        self,
        corners: FloatArray,
        colour: tuple[int, int, int] | npt.NDArray[np.uint8],
        code: int | npt.NDArray[np.int64],
        *,
        group: float,
        distance: float | FloatArray,
        layer: float | FloatArray,
    ) -> None:
        n = len(corners)
        if n == 0:
            return
        self.corners.append(corners)
        self.colours.append(np.broadcast_to(np.asarray(colour, dtype=np.uint8), (n, 3)))
        self.codes.append(np.broadcast_to(np.asarray(code, dtype=np.int64), (n,)))
        rows = np.empty((n, 3))
        rows[:, 0] = group
        rows[:, 1] = distance
        rows[:, 2] = layer
        self.order.append(rows)


def code(cls: int, object_id: int) -> int:
    """A depth frame's first word: class in the top 3 bits, id in the low 13."""
    return (cls << ID_BITS) | (object_id & ((1 << ID_BITS) - 1))


class Renderer:
    """Colour and depth frames of ``scene`` from a camera on ``mount``."""

    def __init__(self, scene: Scene, mount: Mount | None = None) -> None:
        self.scene = scene
        self.mount = mount or Mount()

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

    def rgb(self, camera: CameraModel, distance_m: float) -> npt.NDArray[np.uint8]:
        """The colour frame ``(height, width, 3)``, rows top to bottom."""
        pose = self.pose(distance_m)
        faces = self._faces(pose, camera, distance_m, RANGE_M)
        ids, normals, offsets, colours, _ = self._rasterise(faces, pose, camera, 1)
        distance = _distances(ids, normals, offsets, camera)
        clear = np.exp(distance * np.float32(-1.0 / HAZE_M))[..., None]
        image = colours[ids] * clear + HAZE.astype(np.float32) * (1.0 - clear)
        # the sky, by row (the camera does not roll): zenith above, haze at the horizon
        rays = _rays(camera.width, camera.height, camera.fov_deg)[:, camera.width // 2]
        elevation = rays @ np.array([pose.right[2], pose.up[2], pose.forward[2]])
        blend = np.clip(elevation / 0.4, 0.0, 1.0)[:, None]
        sky = SKY_HORIZON * (1.0 - blend) + SKY_ZENITH * blend
        sky[elevation <= 0.0] = HAZE
        image = np.where((ids == 0)[..., None], sky[:, None, :].astype(np.float32), image)
        return np.asarray(image + 0.5, dtype=np.uint8)

    def depth(
        self, camera: CameraModel, distance_m: float, max_distance_m: float
    ) -> npt.NDArray[np.uint16]:
        """The depth frame ``(height, width, 3)``: class/id, distance scaled to
        ``max_distance_m`` over 0..65535, intensity (|cos| of the incidence) over 0..65535."""
        pose = self.pose(distance_m)
        faces = self._faces(pose, camera, distance_m, max_distance_m)
        ids, normals, offsets, _, codes = self._rasterise(faces, pose, camera, DEPTH_SUPERSAMPLING)
        rays = _rays(camera.width, camera.height, camera.fov_deg)
        cosine = np.abs(np.einsum("hwk,hwk->hw", normals[ids], rays))
        distance = np.abs(offsets[ids]) / np.maximum(cosine, 1e-6)
        seen = (ids > 0) & (distance <= max_distance_m)
        frame = np.zeros((camera.height, camera.width, 3), dtype=np.uint16)
        frame[..., 0] = codes[ids]
        frame[..., 1] = np.round(np.minimum(distance / max_distance_m, 1.0) * 65535.0)
        frame[..., 2] = np.round(np.minimum(cosine, 1.0) * 65535.0)
        frame[~seen] = 0
        return frame

    # --- geometry --------------------------------------------------------------------------

    def _faces(self, pose: Pose, camera: CameraModel, distance_m: float, reach_m: float) -> _Faces:
        faces = _Faces([], [], [], [])
        self._terrain(faces, pose, camera, distance_m, reach_m)
        ahead = min(self.scene.length, distance_m + reach_m)
        bounds = _segment_bounds(distance_m, ahead)
        if len(bounds) >= 2:
            self._track(faces, bounds, distance_m)
            self._balises(faces, bounds, distance_m, ahead)
            self._platforms(faces, bounds, distance_m, ahead)
            self._signals(faces, bounds, distance_m, ahead)
        return faces

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
        faces.add(quads, GRASS, code(TERRAIN, 0), group=0, distance=ring, layer=0)

    def _track(self, faces: _Faces, bounds: FloatArray, camera_m: float) -> None:
        centre, _, right = self.scene.at(bounds)
        section = self.scene.section_at(bounds[:-1]) + 1
        near = bounds[:-1]
        rel = near - camera_m

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
            faces.add(quads, SHOULDER, terrain, group=1, distance=rel, layer=0)
        bed = np.where((rel < SLEEPER_RANGE_M)[:, None], BALLAST, BALLAST_FAR).astype(np.uint8)
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
            faces.add(quads, SLEEPER, codes, group=1, distance=bounds[seg] - camera_m, layer=2)

        rail_codes = (TRACK << ID_BITS) | (section & 0x1FFF)
        inner = GAUGE_M / 2.0 - RAIL_HEAD_M / 2.0
        outer = GAUGE_M / 2.0 + RAIL_HEAD_M / 2.0
        for side in (-1.0, 1.0):
            quads = strip(side * inner, 0.0, side * inner, -RAIL_HEIGHT_M)
            faces.add(quads, RAIL_SIDE, rail_codes, group=1, distance=rel, layer=3)
            quads = strip(side * inner, 0.0, side * outer, 0.0)
            faces.add(quads, RAIL_TOP, rail_codes, group=1, distance=rel, layer=4)

    def _balises(self, faces: _Faces, bounds: FloatArray, camera_m: float, ahead: float) -> None:
        half = BALISE_ALONG_M / 2.0
        across = BALISE_ACROSS_M / 2.0
        low, high = -RAIL_HEIGHT_M, -RAIL_HEIGHT_M + BALISE_HEIGHT_M
        for balise in self.scene.balises:
            d = balise.distance_m
            if not camera_m + NEAR_M + half < d < ahead - half:
                continue
            (c0, c1), _, (r0, r1) = self.scene.at([d - half, d + half])

            def corner(c: FloatArray, r: FloatArray, side: float, z: float) -> FloatArray:
                return np.asarray(c + side * across * r + np.array([0.0, 0.0, z]))

            box = {
                (a, s, z): corner(c, r, s, z)
                for a, c, r in ((0, c0, r0), (1, c1, r1))
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
            colours = np.array([BALISE_SIDE] * 4 + [BALISE_TOP], dtype=np.uint8)
            seg = _segment_of(bounds, np.array([d]))[0]
            faces.add(
                np.array(quads),
                colours,
                code(BALISE, balise.code),
                group=1,
                distance=float(bounds[seg]) - camera_m,
                layer=5 + np.arange(5) / 10.0,
            )

    def _platforms(self, faces: _Faces, bounds: FloatArray, camera_m: float, ahead: float) -> None:
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
            back = side * (PLATFORM_EDGE_M + PLATFORM_DEPTH_M)
            line0, line1 = side * (PLATFORM_EDGE_M + 0.25), side * (PLATFORM_EDGE_M + 0.33)
            for layer, colour, quads in (
                (6.0, PLATFORM_EDGE, _strip(centre, right, edge, BALLAST_TOP_M, edge, top)),
                (6.1, PLATFORM_TOP, _strip(centre, right, edge, top, back, top)),
                (6.2, PLATFORM_LINE, _strip(centre, right, line0, top, line1, top)),
            ):
                faces.add(quads, colour, ident, group=1, distance=rel, layer=layer)

    def _signals(self, faces: _Faces, bounds: FloatArray, camera_m: float, ahead: float) -> None:
        for signal in self.scene.signals:
            d = signal.distance_m
            if not camera_m + 2.0 < d < ahead:
                continue
            (c,), _, (r,) = self.scene.at(d)
            ident = code(SIGNAL, signal.index)
            lateral = signal.side * SIGNAL_OFFSET_M
            quads = np.array(
                [
                    _panel(c, r, lateral, 0.08, TERRAIN_M, 4.2),
                    _panel(c, r, lateral, 0.3, 4.0, 5.4),
                    _panel(c, r, lateral, 0.12, 4.9, 5.2),
                ]
            )
            colours = np.array([MAST, SIGNAL_HEAD, LAMP], dtype=np.uint8)
            seg = _segment_of(bounds, np.array([d]))[0]
            faces.add(
                quads,
                colours,
                ident,
                group=1,
                distance=float(bounds[seg]) - camera_m,
                layer=7 + np.arange(3) / 10.0,
            )

    # --- rasterisation ---------------------------------------------------------------------

    def _rasterise(
        self, faces: _Faces, pose: Pose, camera: CameraModel, supersampling: int
    ) -> tuple[
        npt.NDArray[np.int32],
        npt.NDArray[np.float32],
        npt.NDArray[np.float32],
        npt.NDArray[np.float32],
        npt.NDArray[np.uint16],
    ]:
        """The id buffer (0 = nothing, i = face i) and, per face (index 0: nothing), its
        unit normal and plane offset in camera coordinates, its shaded colour and its depth
        code.

        Pillow fills a polygon from its vertices cut to whole pixels, edges included: up to a
        pixel too much. With ``supersampling`` k the buffer is k times finer and each pixel
        takes the sub-pixel at its centre (k odd), so the coverage is right to 1/k pixel."""
        k = supersampling
        width, height = camera.width * k, camera.height * k
        order = np.concatenate(faces.order)
        rank = np.lexsort((order[:, 2], -order[:, 1], order[:, 0]))
        corners = pose.to_camera(np.concatenate(faces.corners)[rank])
        colours = np.concatenate(faces.colours)[rank].astype(np.float32)
        codes = np.concatenate(faces.codes)[rank].astype(np.uint16)

        normals = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
        norm = np.linalg.norm(normals, axis=1)
        keep = (norm > 1e-12) & (corners[:, :, 2] > NEAR_M).any(axis=1)
        corners, colours, codes = corners[keep], colours[keep], codes[keep]
        normals = normals[keep] / norm[keep][:, None]
        offsets = np.einsum("ij,ij->i", normals, corners.mean(axis=1))
        towards = offsets > 0.0  # the normal must point to the camera (at the origin)
        normals[towards] *= -1.0
        offsets[towards] *= -1.0
        sun = pose.to_camera(pose.position + SUN / np.linalg.norm(SUN))
        light = 0.62 + 0.38 * np.clip(normals @ sun, 0.0, 1.0)
        colours = colours * light[:, None].astype(np.float32)

        focal = camera.focal_px * k
        z = np.maximum(corners[:, :, 2], NEAR_M)
        u = focal * corners[:, :, 0] / z + width / 2.0
        v = -focal * corners[:, :, 1] / z + height / 2.0
        inside = (corners[:, :, 2] > NEAR_M).all(axis=1)
        visible = ~inside | (
            (u.max(axis=1) >= -1)
            & (u.min(axis=1) <= width + 1)
            & (v.max(axis=1) >= -1)
            & (v.min(axis=1) <= height + 1)
        )
        buffer = Image.new("I", (width, height), 0)
        draw = ImageDraw.Draw(buffer)
        flat = np.stack([u, v], axis=2).reshape(len(u), 8).tolist()
        for index in np.flatnonzero(visible).tolist():
            if inside[index]:
                points = flat[index]
            else:
                points = _clipped(corners[index], focal, width, height)
                if len(points) < 6:
                    continue
            draw.polygon(points, fill=index + 1)
        ids = np.asarray(buffer, dtype=np.int32)[k // 2 :: k, k // 2 :: k]
        none = np.zeros((1, 3), dtype=np.float32)
        return (
            ids,
            np.concatenate([none, normals.astype(np.float32)]),
            np.concatenate([[np.float32(0.0)], offsets.astype(np.float32)]),
            np.concatenate([none, colours]),
            np.concatenate([[np.uint16(0)], codes]),
        )


def _distances(
    ids: npt.NDArray[np.int32],
    normals: npt.NDArray[np.float32],
    offsets: npt.NDArray[np.float32],
    camera: CameraModel,
) -> npt.NDArray[np.float32]:
    """Distance from the camera to what each pixel sees (0 where nothing)."""
    rays = _rays(camera.width, camera.height, camera.fov_deg)
    n = normals[ids]
    cosine = np.abs(n[..., 0] * rays[..., 0] + n[..., 1] * rays[..., 1] + n[..., 2] * rays[..., 2])
    return np.asarray(np.abs(offsets[ids]) / np.maximum(cosine, np.float32(1e-6)))


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


def _clipped(quad: FloatArray, focal: float, width: int, height: int) -> list[float]:
    """A quad cut at the near plane (Sutherland-Hodgman), projected: flat [u0, v0, u1, ...]."""
    points: list[FloatArray] = []
    for i in range(4):
        a, b = quad[i], quad[(i + 1) % 4]
        a_in, b_in = a[2] > NEAR_M, b[2] > NEAR_M
        if a_in:
            points.append(a)
        if a_in != b_in:
            t = (NEAR_M - a[2]) / (b[2] - a[2])
            points.append(a + t * (b - a))
    flat: list[float] = []
    for p in points:
        flat += [focal * p[0] / p[2] + width / 2.0, -focal * p[1] / p[2] + height / 2.0]
    return flat


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
