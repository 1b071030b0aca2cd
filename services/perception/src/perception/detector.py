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
5. **Bound.** At most ``max_detections`` (``MAX_DETECTIONS``, 64) per frame, the nearest: a
   frame of yellow confetti (a 4K frame of 2-pixel dots has 670,009 blobs) gives 64
   detections and says how many more it left out (``Found.omitted``), never a 35 MB answer.

Every blob is measured at once, as arrays (boxes, sizes, distances), so a frame's time does not
grow with a Python loop over its blobs.

The distance ahead is along the ground from the camera, which on a curve is the chord, not
the arc (0.1 m short at 50 m on a 185 m radius).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage

Pixels = npt.NDArray[np.uint8]
Mask = Callable[[Pixels], npt.NDArray[np.bool_]]
"""Which pixels are a balise's: ``yellow_mask``, or the learned detector's model."""
BALISE_WIDTH_M = 0.52
"""Across the track: a blob's expected width in pixels at a distance."""


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


MAX_DETECTIONS = 64
"""Detections reported per frame at most (the nearest); a real scene has a few balises."""


@dataclass(frozen=True, kw_only=True)
class Found:
    """What one frame showed."""

    detections: list[Detection]
    """Nearest first, at most ``max_detections``."""
    omitted: int = 0
    """Balise-like blobs in range left out by the bound (the farthest)."""


def detect(
    rgb: Pixels,
    intrinsics: Intrinsics,
    mounting: Mounting,
    *,
    max_range_m: float = 40.0,
    min_pixels: int = 2,
    max_detections: int = MAX_DETECTIONS,
    shape: BaliseShape = BALISE,
) -> list[Detection]:
    """Every balise in the frame within ``max_range_m``, nearest first (at most
    ``max_detections``: ``find`` says how many more there were)."""
    return find(
        rgb,
        intrinsics,
        mounting,
        max_range_m=max_range_m,
        min_pixels=min_pixels,
        max_detections=max_detections,
        shape=shape,
    ).detections


def find(
    rgb: Pixels,
    intrinsics: Intrinsics,
    mounting: Mounting,
    *,
    max_range_m: float = 40.0,
    min_pixels: int = 2,
    max_detections: int = MAX_DETECTIONS,
    shape: BaliseShape = BALISE,
    mask: Mask = yellow_mask,
    max_width_ratio: float | None = None,
) -> Found:
    """The balises in the frame within ``max_range_m``, nearest first, at most
    ``max_detections`` of them, and how many more there were. ``mask`` says which pixels are
    a balise's; with ``max_width_ratio`` a blob wider than that many balise widths at its
    distance is no balise (a platform edge's line, a rail's glint)."""
    found = mask(rgb)
    rows = np.flatnonzero(found.any(axis=1))
    if rows.size == 0:
        return Found(detections=[])
    # labelled on the rows that have any pixel: the same blobs, numbered in the same order
    first = int(rows[0])
    labels, count = ndimage.label(found[first : rows[-1] + 1], structure=np.ones((3, 3), bool))
    top, bottom, left, right, sizes = _boxes(labels, count)
    top += first
    bottom += first
    kept = np.flatnonzero(sizes >= min_pixels)
    top, bottom, left, right, sizes = (a[kept] for a in (top, bottom, left, right, sizes))
    u = (left + right) / 2.0
    near_ahead, near_lateral = _ground(u, bottom + 0.5, mounting.height_m + shape.bottom_m,
                                       intrinsics, mounting)  # fmt: skip
    far_ahead, far_lateral = _ground(u, top - 0.5, mounting.height_m + shape.top_m,
                                     intrinsics, mounting)  # fmt: skip
    distance = (near_ahead + far_ahead) / 2.0  # NaN above the horizon
    within = distance <= max_range_m
    if max_width_ratio is not None:
        expected_px = BALISE_WIDTH_M * intrinsics.fx / np.maximum(distance, 1.0)
        within &= (right - left + 1) <= max_width_ratio * np.maximum(expected_px, 1.0)
    inside = np.flatnonzero(within)
    order = inside[np.argsort(distance[inside], kind="stable")]
    shown = order[: max(max_detections, 0)]
    lateral = (near_lateral + far_lateral) / 2.0
    # a balise of 0.52 m across at this distance is this many pixels wide
    expected = BALISE_WIDTH_M * intrinsics.fx / np.maximum(distance[shown], 1.0)
    confidence = np.minimum(1.0, (right[shown] - left[shown] + 1) / np.maximum(expected, 1.0))
    detections = [
        Detection(
            left=int(left[i]),
            top=int(top[i]),
            right=int(right[i]),
            bottom=int(bottom[i]),
            distance_ahead_m=float(distance[i]),
            lateral_m=float(lateral[i]),
            confidence=round(float(c), 3),
            pixels=int(sizes[i]),
        )
        for i, c in zip(shown, confidence, strict=True)
    ]
    return Found(detections=detections, omitted=len(order) - len(shown))


def _boxes(labels: npt.NDArray[np.integer[Any]], count: int) -> tuple[npt.NDArray[np.int64], ...]:
    """Top, bottom, left and right (inclusive) and the size in pixels of blobs 1..count."""
    width = labels.shape[1]
    flat = labels.ravel()
    where = np.flatnonzero(flat)
    which = flat[where] - 1
    rows, cols = np.divmod(where, width)
    top = np.full(count, labels.shape[0], dtype=np.int64)
    left = np.full(count, width, dtype=np.int64)
    bottom = np.full(count, -1, dtype=np.int64)
    right = np.full(count, -1, dtype=np.int64)
    np.minimum.at(top, which, rows)
    np.maximum.at(bottom, which, rows)
    np.minimum.at(left, which, cols)
    np.maximum.at(right, which, cols)
    return top, bottom, left, right, np.bincount(which, minlength=count)


def _ground(
    u: npt.NDArray[np.floating[Any]],
    v: npt.NDArray[np.floating[Any]],
    depth_m: float,
    intrinsics: Intrinsics,
    mounting: Mounting,
) -> tuple[npt.NDArray[np.floating[Any]], npt.NDArray[np.floating[Any]]]:
    """``ground_distance`` of many pixels at once; NaN where a ray is above the horizon."""
    x = (u - intrinsics.cx) / intrinsics.fx
    y = (v - intrinsics.cy) / intrinsics.fy  # down
    pitch = math.radians(mounting.pitch_deg)
    down = y * math.cos(pitch) + math.sin(pitch)
    ahead = -y * math.sin(pitch) + math.cos(pitch)
    t = np.where(down > 1e-9, depth_m / np.where(down > 1e-9, down, 1.0), np.nan)
    return np.hypot(x * t, ahead * t), x * t
