"""Terrain tiles under the track: ``TILES/<name>.t`` with its height, flag, error and normal
buffers, as OpenRails' ``TerrainFile`` and tile manager read them.

A tile is 2048 m square, sampled every 8 m (256 x 256 samples, ``terrain_sample_size 8``).
Its heights are ``_y.raw``: unsigned 16-bit little-endian values, row by row from the north
edge, west to east in a row; sample ``(ix, iz)`` lies at ``x = 8 ix - 1024``, ``z = 1024 - 8
iz`` from the tile's centre, and its height is ``floor + value * scale`` (the ``.t`` file's
``terrain_sample_floor`` and ``terrain_sample_scale``). ``_f.raw`` holds one flag byte per
sample (0: drawn); ``_e.raw`` (one byte per sample, 0) and ``_n.raw`` (three bytes per sample,
an upward normal) are named by the ``.t`` file as MSTS names them; OpenRails' viewer does not
read them. The file names are MSTS' quadtree names of the tile
(:func:`coupler_railway.openrails.world.terrain_tile_name`).

Where: every tile that holds track and its eight neighbours (the tiles that have world
files). Heights: each sample is as high as the point of the track nearest to it (the track's
own height, from railML), so the ground is level across the track and follows its gradient
along it; the resolution of the heights is ``scale`` (at most 2 mm). One terrain shader with
one ground colour (``TERRTEX/CouplerGround.ace``); 16 x 16 patches of 128 m.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from coupler_railway.openrails.ace import write_ace
from coupler_railway.openrails.stf import StfWriter
from coupler_railway.openrails.world import TILE_SIZE_M, terrain_tile_name

SAMPLES = 256
SAMPLE_SIZE_M = 8.0
PATCHES = 16
GROUND_TEXTURE = "CouplerGround.ace"
GROUND_COLOUR = (96, 110, 72, 255)
MIN_SCALE_M = 0.001
"""The finest height step written (a tile whose heights span more than 65.5 m gets a coarser
one: its span / 65535)."""


@dataclass(frozen=True)
class TrackProfile:
    """The track as points on the world plane with their heights, in order along each line:
    ``lines`` of ``(east, north, height)`` arrays (world-plane metres)."""

    lines: tuple[np.ndarray, ...]

    def heights(self, east: np.ndarray, north: np.ndarray) -> np.ndarray:
        """The height of the track point nearest to each ``(east, north)`` (projected onto
        the polyline, its height interpolated linearly along the segment)."""
        points = np.concatenate([line[:, :2] for line in self.lines])
        tree = cKDTree(points)
        query = np.column_stack([east.ravel(), north.ravel()])
        _, nearest = tree.query(query)
        best_distance = np.full(len(query), np.inf)
        best_height = np.zeros(len(query))
        offset = 0
        starts = []
        for line in self.lines:
            starts.append(offset)
            offset += len(line)
        ends = [s + len(line) for s, line in zip(starts, self.lines, strict=True)]
        first = np.searchsorted(np.array(ends), nearest, side="right")
        all_points = np.concatenate(self.lines)
        for step in (-1, 0):  # the segment before and the segment after the nearest point
            a = nearest + step
            b = a + 1
            line_start = np.array(starts)[first]
            line_end = np.array(ends)[first]
            valid = (a >= line_start) & (b < line_end)
            a = np.where(valid, a, nearest)
            b = np.where(valid, b, nearest)
            pa, pb = all_points[a], all_points[b]
            d = pb[:, :2] - pa[:, :2]
            length2 = np.maximum(np.sum(d * d, axis=1), 1e-12)
            t = np.clip(np.sum((query - pa[:, :2]) * d, axis=1) / length2, 0.0, 1.0)
            t = np.where(valid, t, 0.0)
            foot = pa[:, :2] + d * t[:, None]
            distance = np.hypot(*(query - foot).T)
            height = pa[:, 2] + (pb[:, 2] - pa[:, 2]) * t
            closer = distance < best_distance
            best_distance = np.where(closer, distance, best_distance)
            best_height = np.where(closer, height, best_height)
        return best_height.reshape(east.shape)


def sample_grid(tile_x: int, tile_z: int) -> tuple[np.ndarray, np.ndarray]:
    """World-plane ``(east, north)`` of every sample of a tile, rows from the north edge."""
    ix = np.arange(SAMPLES)
    x = ix * SAMPLE_SIZE_M - TILE_SIZE_M / 2.0
    z = TILE_SIZE_M / 2.0 - ix * SAMPLE_SIZE_M
    east, north = np.meshgrid(tile_x * TILE_SIZE_M + x, tile_z * TILE_SIZE_M + z)
    return east, north


def quantize(heights: np.ndarray) -> tuple[float, float, np.ndarray]:
    """``(floor, scale, values)`` with ``floor + values * scale`` within ``scale / 2`` of the
    heights (floor and scale as single-precision floats, as OpenRails reads them)."""
    low, high = float(heights.min()), float(heights.max())
    floor = float(np.float32(low))
    if floor > low:
        floor = float(np.nextafter(np.float32(low), np.float32(-np.inf)))
    scale = float(np.float32(max(MIN_SCALE_M, (high - floor) / 65535.0 * 1.0001)))
    values = np.clip(np.rint((heights - floor) / scale), 0, 65535).astype("<u2")
    return floor, scale, values


def write_tile(folder: Path, tile_x: int, tile_z: int, profile: TrackProfile) -> list[str]:
    """One terrain tile: its ``.t`` and buffers in ``folder/TILES``; returns the file names."""
    name = terrain_tile_name(tile_x, tile_z)
    east, north = sample_grid(tile_x, tile_z)
    floor, scale, values = quantize(profile.heights(east, north))
    tiles = folder / "TILES"
    tiles.mkdir(parents=True, exist_ok=True)
    (tiles / f"{name}_y.raw").write_bytes(values.tobytes())
    (tiles / f"{name}_f.raw").write_bytes(bytes(SAMPLES * SAMPLES))
    (tiles / f"{name}_e.raw").write_bytes(bytes(SAMPLES * SAMPLES))
    (tiles / f"{name}_n.raw").write_bytes(bytes([127, 255, 127]) * (SAMPLES * SAMPLES))
    mean = floor + float(values.mean()) * scale
    spread = float(values.max() - values.min()) * scale
    stf = StfWriter("JINX0t1t")
    stf.block("terrain")
    stf.line("terrain_errthreshold_scale", 1)
    stf.line("terrain_alwaysselect_maxdist", 0)
    stf.block("terrain_samples")
    stf.line("terrain_nsamples", SAMPLES)
    stf.line("terrain_sample_rotation", 0)
    stf.line("terrain_sample_floor", floor)
    stf.line("terrain_sample_scale", scale)
    stf.line("terrain_sample_size", SAMPLE_SIZE_M)
    for kind in ("y", "f", "e", "n"):
        stf.line(f"terrain_sample_{kind}buffer", f"{name}_{kind}.raw")
    stf.end()
    stf.block("terrain_shaders", 1)
    stf.block("terrain_shader", "CouplerGround")
    stf.block("terrain_texslots", 1)
    stf.line("terrain_texslot", GROUND_TEXTURE, 1, 0)
    stf.end()
    stf.block("terrain_uvcalcs", 1)
    stf.line("terrain_uvcalc", 1, 0, 0, 0)
    stf.end()
    stf.end()
    stf.end()
    stf.block("terrain_patches")
    stf.block("terrain_patchsets", 1)
    stf.block("terrain_patchset")
    stf.line("terrain_patchset_distance", 0)
    stf.line("terrain_patchset_npatches", PATCHES)
    stf.block("terrain_patchset_patches")
    size = TILE_SIZE_M / PATCHES
    step = 1.0 / PATCHES
    for pz in range(PATCHES):
        for px in range(PATCHES):
            stf.line(
                "terrain_patchset_patch",
                "00000000",
                size / 2.0 + px * size,  # centre from the tile's north-west corner
                mean,
                -(size / 2.0 + pz * size),
                spread,
                0,
                size / 2.0 * 2**0.5,
                0,
                px * step,
                pz * step,
                step / (SAMPLES / PATCHES),
                0,
                0,
                step / (SAMPLES / PATCHES),
                0,
            )
    for _ in range(5):
        stf.end()
    stf.save(tiles / f"{name}.t")
    return [f"TILES/{name}{suffix}" for suffix in (".t", "_y.raw", "_f.raw", "_e.raw", "_n.raw")]


def write_terrain(folder: Path, tiles: list[tuple[int, int]], profile: TrackProfile) -> list[str]:
    """Every tile of ``tiles`` and the ground texture; returns the files written."""
    written = [name for tile in tiles for name in write_tile(folder, *tile, profile)]
    write_ace(folder / "TERRTEX" / GROUND_TEXTURE, GROUND_COLOUR)
    return [*written, f"TERRTEX/{GROUND_TEXTURE}"]


def read_heights(t_file_floor: float, scale: float, raw: bytes) -> np.ndarray:
    """Heights of a ``_y.raw`` buffer (rows from the north edge), as OpenRails computes them."""
    values = np.frombuffer(raw, dtype="<u2").reshape(SAMPLES, SAMPLES).astype(np.float32)
    return values * np.float32(scale) + np.float32(t_file_floor)
