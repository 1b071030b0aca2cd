"""Balises in a camera frame: yellow blobs, placed on the ground by the camera's geometry.

The detector is deliberately simple -- an example of a system under test, not a product:

1. **Colour.** A pixel is balise-yellow when red and green are strong and blue is weak
   (``yellow_mask``): the paint of a Eurobalise seen in daylight.
2. **Blobs.** Connected yellow pixels (8-neighbourhood) are labelled with
   ``scipy.ndimage.label`` and boxed with ``find_objects``; blobs of fewer than
   ``min_pixels`` pixels are noise.
3. **Distance** from the ground-plane geometry of the camera: its intrinsics (fx, fy, cx, cy,
   from the Image), its mounting (height above the top of the rails, pitch down) and what a
   balise is (a box on the sleepers, ``BALISE``). The blob's lowest row is the balise's near
   bottom edge, on the plane of the sleepers' tops; its highest row its far top edge, on the
   plane of its top. Each row's ray meets its plane at a distance ahead; the balise's centre
   is their mean. The ground is taken as flat and the camera as level across (no roll).
4. **Range.** Blobs farther than ``max_range_m`` (40 m) are not reported: beyond, with an
   800 x 600 camera of 45 degrees, a pixel row spans more than a metre of track and the
   balises of a group (3 m apart) merge into one blob.

The distance ahead is along the ground from the camera, which on a curve is the chord, not
the arc (0.1 m short at 50 m on a 185 m radius).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage

Pixels = npt.NDArray[np.uint8]


@dataclass(frozen=True, kw_only=True)
class Intrinsics:
    """Pinhole intrinsics in OpenCV's convention (pixel centres at whole numbers)."""

    fx: float
    fy: float
    cx: float
    cy: float


@dataclass(frozen=True, kw_only=True)
class Mounting:
    """Where the camera is: above the top of the rails, looking along the track."""

    height_m: float = 2.5
    pitch_deg: float = 4.0
    """Down from the track's direction."""


@dataclass(frozen=True, kw_only=True)
class BaliseShape:
    """What the detector assumes a balise is (a Eurobalise on the sleepers)."""

    length_m: float = 0.36
    """Along the track."""
    bottom_m: float = 0.172
    """Below the top of the rails: the top of the sleepers it lies on."""
    top_m: float = 0.072
    """Below the top of the rails: its own top."""


BALISE = BaliseShape()


@dataclass(frozen=True, kw_only=True)
class Detection:
    """One balise seen in a frame."""

    left: int
    top: int
    right: int
    bottom: int
    """Its pixel box, inclusive."""
    distance_ahead_m: float
    """From the camera to the balise's centre, along the ground."""
    lateral_m: float
    """Right of the camera's axis (negative: left)."""
    confidence: float
    """0..1: how many yellow pixels there are for a balise that far, and how yellow."""
    pixels: int


def yellow_mask(rgb: Pixels) -> npt.NDArray[np.bool_]:
    """Balise-yellow pixels: red and green strong, blue weak, green a bit below red."""
    r = rgb[..., 0].astype(np.int16)
    g = rgb[..., 1].astype(np.int16)
    b = rgb[..., 2].astype(np.int16)
    return (r > 110) & (g > 80) & (r - b > 90) & (g - b > 60) & (g <= r) & (g * 10 >= r * 6)


def ground_distance(
    u: float, v: float, depth_m: float, intrinsics: Intrinsics, mounting: Mounting
) -> tuple[float, float] | None:
    """Where the ray through pixel (u, v) meets the plane ``depth_m`` below the camera:
    (distance ahead along the ground, lateral offset), or None above the horizon."""
    x = (u - intrinsics.cx) / intrinsics.fx
    y = (v - intrinsics.cy) / intrinsics.fy  # down
    pitch = math.radians(mounting.pitch_deg)
    down = y * math.cos(pitch) + math.sin(pitch)
    ahead = -y * math.sin(pitch) + math.cos(pitch)
    if down <= 1e-9:
        return None
    t = depth_m / down
    return math.hypot(x * t, ahead * t), x * t


def detect(
    rgb: Pixels,
    intrinsics: Intrinsics,
    mounting: Mounting,
    *,
    max_range_m: float = 40.0,
    min_pixels: int = 2,
    shape: BaliseShape = BALISE,
) -> list[Detection]:
    """Every balise in the frame within ``max_range_m``, nearest first."""
    mask = yellow_mask(rgb)
    labels, count = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    if count == 0:
        return []
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    found: list[Detection] = []
    for index, box in enumerate(ndimage.find_objects(labels), start=1):
        if box is None or sizes[index] < min_pixels:
            continue
        rows, cols = box
        top, bottom = rows.start, rows.stop - 1
        left, right = cols.start, cols.stop - 1
        u = (left + right) / 2.0
        near = ground_distance(u, bottom + 0.5, mounting.height_m + shape.bottom_m,
                               intrinsics, mounting)  # fmt: skip
        far = ground_distance(u, top - 0.5, mounting.height_m + shape.top_m, intrinsics, mounting)
        if near is None or far is None:
            continue
        distance = (near[0] + far[0]) / 2.0
        if distance > max_range_m:
            continue
        lateral = (near[1] + far[1]) / 2.0
        # a balise of 0.52 m across at this distance is this many pixels wide
        expected = 0.52 * intrinsics.fx / max(distance, 1.0)
        confidence = min(1.0, (right - left + 1) / max(expected, 1.0))
        found.append(
            Detection(
                left=left,
                top=top,
                right=right,
                bottom=bottom,
                distance_ahead_m=distance,
                lateral_m=lateral,
                confidence=round(confidence, 3),
                pixels=int(sizes[index]),
            )
        )
    return sorted(found, key=lambda d: d.distance_ahead_m)
