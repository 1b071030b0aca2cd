"""Where a balise appears in a train camera's frame: a pinhole camera at the train's front,
``height_m`` above the top of the rails, looking along the track and pitched ``pitch_deg``
down (the OpenRails mock's mounting, and the perception participant's assumption).

The projection takes the ground as flat and the track as straight between the camera and the
balise: exact on the straight, level stretches, a few pixels off on a gradient change, and on
a curve the box is drawn where the balise would be on the straight (on a 185 m radius, 2.4 m
to the side of it at 30 m ahead). It is the ground truth the scorer draws until the renderer's
labels (a box per balise per frame) are recorded with the run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

BALISE_ALONG_M = 0.36
BALISE_ACROSS_M = 0.52
BALISE_BOTTOM_M = 0.172
"""Below the top of the rails: the top of the sleepers a Eurobalise lies on."""
BALISE_TOP_M = 0.072
"""Below the top of the rails: its own top."""


@dataclass(frozen=True, kw_only=True)
class Camera:
    """A frame's intrinsics (OpenCV's convention, as ``coupler.v1.CameraIntrinsics``) and the
    camera's mounting."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    height_m: float = 2.5
    pitch_deg: float = 4.0

    def pixel(self, ahead_m: float, lateral_m: float, below_m: float) -> tuple[float, float] | None:
        """(u, v) of a point ``ahead_m`` ahead along the ground, ``lateral_m`` right of the
        camera's axis and ``below_m`` below the camera; None behind the camera."""
        pitch = math.radians(self.pitch_deg)
        z = ahead_m * math.cos(pitch) + below_m * math.sin(pitch)
        if z <= 1e-6:
            return None
        y = -ahead_m * math.sin(pitch) + below_m * math.cos(pitch)
        return self.fx * lateral_m / z + self.cx, self.fy * y / z + self.cy

    def balise_box(
        self, distance_ahead_m: float, lateral_m: float = 0.0
    ) -> tuple[int, int, int, int] | None:
        """The pixel box (left, top, right, bottom, inclusive) of a balise whose centre is
        ``distance_ahead_m`` ahead, clipped to the frame; None when none of it is in the frame."""
        corners = []
        for along in (-BALISE_ALONG_M / 2, BALISE_ALONG_M / 2):
            for across in (-BALISE_ACROSS_M / 2, BALISE_ACROSS_M / 2):
                for below in (BALISE_BOTTOM_M, BALISE_TOP_M):
                    at = self.pixel(
                        distance_ahead_m + along, lateral_m + across, self.height_m + below
                    )
                    if at is None:
                        return None
                    corners.append(at)
        us, vs = [u for u, _ in corners], [v for _, v in corners]
        left, right = round(min(us)), round(max(us))
        top, bottom = round(min(vs)), round(max(vs))
        if right < 0 or bottom < 0 or left >= self.width or top >= self.height:
            return None
        return (max(left, 0), max(top, 0), min(right, self.width - 1), min(bottom, self.height - 1))
