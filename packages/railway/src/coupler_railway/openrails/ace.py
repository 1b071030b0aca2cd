"""MSTS textures (``.ace``): the uncompressed, structured form OpenRails' ``AceFile`` reads.

Layout (little endian): ``SIMISA@@@@@@@@@@`` (16 ASCII bytes), then from the data's base:
int32 1, options 0 (no mipmaps, structured scan lines), width, height, surface format 0x0E,
channel count, 128 bytes of zeros; per channel a uint64 size in bits (8) and a uint64 type
(3 red, 4 green, 5 blue, 6 alpha); a table of int32 offsets (from the data's base) of every
scan line; then each scan line: the channels one after another, ``width`` bytes each.
The route's textures are single colours (solid 8 x 8 images), named by the colour they carry.
"""

from __future__ import annotations

import struct
from pathlib import Path

SIGNATURE = b"SIMISA@@@@@@@@@@"
SIZE = 8
"""Width and height of the solid textures."""
_CHANNELS = (3, 4, 5, 6)
"""Red, green, blue, alpha."""


def ace_bytes(rgba: tuple[int, int, int, int], size: int = SIZE) -> bytes:
    """An ``size`` x ``size`` texture of one colour."""
    header = struct.pack("<6i", 1, 0, size, size, 0x0E, len(_CHANNELS)) + bytes(128)
    channels = b"".join(struct.pack("<2Q", 8, kind) for kind in _CHANNELS)
    table_at = len(header) + len(channels)
    line = b"".join(bytes([value]) * size for value in rgba)
    first = table_at + 4 * size
    table = b"".join(struct.pack("<i", first + row * len(line)) for row in range(size))
    return SIGNATURE + header + channels + table + line * size


def read_ace(data: bytes) -> tuple[int, int, list[list[tuple[int, int, int, int]]]]:
    """``(width, height, rows of RGBA pixels)`` of an uncompressed structured texture;
    ValueError naming what is wrong otherwise (the reader the tests use)."""
    if not data.startswith(SIGNATURE):
        raise ValueError(f"starts with {data[:16]!r}, not {SIGNATURE!r}")
    base = len(SIGNATURE)
    one, options, width, height, _, count = struct.unpack_from("<6i", data, base)
    if one != 1 or options != 0:
        raise ValueError(f"is not an uncompressed structured texture (1 {one}, options {options})")
    if not (0 < width <= 4096 and 0 < height <= 4096 and 0 < count <= 8):
        raise ValueError(f"has {width} x {height} pixels in {count} channels")
    at = base + 24 + 128
    kinds = []
    for _ in range(count):
        bits, kind = struct.unpack_from("<2Q", data, at)
        if bits != 8 or not 2 <= kind <= 6:
            raise ValueError(f"has a channel of {bits} bits, type {kind}")
        kinds.append(kind)
        at += 16
    offsets = struct.unpack_from(f"<{height}i", data, at)
    rows = []
    for offset in offsets:
        start = base + offset
        if start + width * count > len(data):
            raise ValueError(f"has a scan line at {offset} beyond its {len(data)} bytes")
        planes = {kinds[c]: data[start + c * width : start + (c + 1) * width] for c in range(count)}
        alpha = planes.get(6, bytes([255]) * width)
        rows.append([(planes[3][x], planes[4][x], planes[5][x], alpha[x]) for x in range(width)])
    return width, height, rows


def write_ace(path: Path, rgba: tuple[int, int, int, int]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(ace_bytes(rgba))
    return path
