"""The learned detector's per-pixel work as one compiled pass (numba): each row's median, the
candidates, their features and the walk down the tree, a pixel at a time.

``learned.PixelModel.probability_numpy`` builds the float frame, its row medians (a
partition of every row), the difference frame, the features of every candidate and then walks
the tree a level at a time over all of them: 13 ms a noon frame and 20 ms a night one (a
hundred thousand candidates) on one core here, more than the mock takes to render the frame.
This kernel gives the same probabilities, bit for bit, in a single visit of each pixel: the
median of a row of bytes is read from a 256-bin count of them, and the arithmetic is numpy's,
in float32 and in the same order (no ``fastmath``). ``tests/test_learned.py`` holds the two
to the same output over rendered frames under several conditions. Compiled by ``warm`` and
cached beside this file (``cache=True``; NUMBA_CACHE_DIR elsewhere).
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

_jit = numba.njit(cache=True, nogil=True, fastmath=False, error_model="numpy")

SCALE = np.arange(256, dtype=np.float32) / np.float32(255.0)
"""A byte as the numpy path has it: ``rgb.astype(np.float32) / 255.0``."""


@_jit
def _kth(counts, k):  # type: ignore[no-untyped-def]
    """The k-th smallest (from 0) of the bytes counted in ``counts`` (256 bins)."""
    seen = 0
    for value in range(256):
        seen += counts[value]
        if seen > k:
            return value
    return 255


@_jit
def _row_medians(rgb, scale, out):  # type: ignore[no-untyped-def]
    """``out[row, channel]`` = numpy's median of the row's values of the channel (the mean
    of the two middle ones of an even row, in float32)."""
    height, width, channels = rgb.shape
    counts = np.zeros(256, dtype=np.int64)
    for row in range(height):
        for channel in range(channels):
            counts[:] = 0
            for column in range(width):
                counts[rgb[row, column, channel]] += 1
            if width % 2:
                out[row, channel] = scale[_kth(counts, width // 2)]
            else:
                low = scale[_kth(counts, width // 2 - 1)]
                high = scale[_kth(counts, width // 2)]
                out[row, channel] = (low + high) / np.float32(2.0)


@_jit
def probability(rgb, scale, feature, threshold, left, right, leaf, depth, out):  # type: ignore[no-untyped-def]
    """``out[row, column]``: the probability the tree gives the pixel, 0 where it is no
    candidate (``learned.candidates``: red and green above the row's median by more than
    blue is)."""
    height, width, _ = rgb.shape
    medians = np.empty((height, 3), dtype=np.float32)
    _row_medians(rgb, scale, medians)
    x = np.empty(11, dtype=np.float32)
    for row in range(height):
        mr, mg, mb = medians[row, 0], medians[row, 1], medians[row, 2]
        for column in range(width):
            r = scale[rgb[row, column, 0]]
            g = scale[rgb[row, column, 1]]
            b = scale[rgb[row, column, 2]]
            dr, dg, db = r - mr, g - mg, b - mb
            if not (dr > db and dg > db):
                out[row, column] = 0.0
                continue
            size = abs(dr) + abs(dg) + abs(db) + np.float32(0.03)
            x[0], x[1], x[2], x[3], x[4] = r, g, b, r - b, g - b
            x[5], x[6], x[7], x[8], x[9] = dr, dg, db, dr - db, dg - db
            x[10] = (dr + dg - np.float32(2.0) * db) / size
            node = 0
            for _ in range(depth):  # a leaf's children are itself
                node = left[node] if x[feature[node]] <= threshold[node] else right[node]
            out[row, column] = leaf[node]


def warm() -> None:
    """Compile the kernel (or load it from numba's cache) on a tiny frame: the participant
    does so when a run asks for the learned detector, at Initialize."""
    tiny = np.zeros((2, 2, 3), dtype=np.uint8)
    zero, one = np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.float32)
    probability(tiny, SCALE, zero, one, zero, zero, one, 1, np.empty((2, 2), np.float32))


def frame_probability(
    rgb: npt.NDArray[np.uint8],
    feature: npt.NDArray[np.int64],
    threshold: npt.NDArray[np.float32],
    left: npt.NDArray[np.int64],
    right: npt.NDArray[np.int64],
    leaf: npt.NDArray[np.float32],
    depth: int,
) -> npt.NDArray[np.float32]:
    """Each pixel's probability, in the frame's shape (``probability``)."""
    out = np.empty(rgb.shape[:2], dtype=np.float32)
    probability(np.ascontiguousarray(rgb), SCALE, feature, threshold, left, right, leaf, depth, out)
    return out
