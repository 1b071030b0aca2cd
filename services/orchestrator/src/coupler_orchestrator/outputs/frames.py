"""Camera frames in results: numbered PNG files, never text in results.csv.

A column carrying ``coupler.v1.Image`` (``proto/coupler/v1/sensors.proto``) is a frame column.
results.csv leaves frame columns out unless ``--output-variables`` picks them; a picked one is
written as ``frames/<Component.channel>/<point>.png`` under the run folder (``point``: the
communication point's index, 0 at t_0), and its cell holds that relative file name. PNG is
written with the standard library (zlib): ``rgb8`` as 8-bit RGB, ``depth16-class-id`` as 16-bit
RGB (class and id, distance, intensity), any other encoding as its raw bytes (``.bin``).
``png`` is also what the monitor page serves as a channel's latest frame.
"""

from __future__ import annotations

import array
import struct
import sys
import zlib
from pathlib import Path

from google.protobuf.message import DecodeError

from coupler.v1.sensors_pb2 import Image
from coupler_orchestrator.observer import Column

IMAGE = Image.DESCRIPTOR.full_name
"""The message a frame column carries."""
FOLDER = "frames"
"""Where frames go in a run folder."""
_LAYOUTS = {"rgb8": (8, 3), "depth16-class-id": (16, 6)}
"""Encoding -> (PNG bit depth, bytes per pixel)."""


def is_frame(column: Column) -> bool:
    """Whether ``column`` carries camera frames (``coupler.v1.Image``)."""
    return column.type == "Binary" and column.message_type == IMAGE


def read_image(data: bytes) -> Image | None:
    """The Image in ``data``; None when there is none (empty bytes, or not an Image)."""
    if not data:
        return None
    image = Image()
    try:
        image.ParseFromString(data)
    except DecodeError:
        return None
    return image


def png(image: Image, level: int = 6) -> bytes | None:
    """``image`` as a PNG file; None for an encoding PNG cannot show, or a size that does not
    match the data."""
    layout = _LAYOUTS.get(image.encoding)
    if layout is None or not image.width or not image.height:
        return None
    depth, pixel = layout
    stride = image.width * pixel
    data = image.data
    if len(data) != stride * image.height:
        return None
    if depth == 16 and sys.byteorder == "little":  # PNG's samples are big-endian
        samples = array.array("H", data)
        samples.byteswap()
        data = samples.tobytes()
    rows = b"".join(b"\0" + data[r * stride : (r + 1) * stride] for r in range(image.height))
    header = struct.pack(">IIBBBBB", image.width, image.height, depth, 2, 0, 0, 0)
    return b"".join(
        (
            b"\x89PNG\r\n\x1a\n",
            _chunk(b"IHDR", header),
            _chunk(b"IDAT", zlib.compress(rows, level)),
            _chunk(b"IEND", b""),
        )
    )


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


class FrameStore:
    """Writes the frames of picked frame columns into ``<run folder>/frames/``."""

    def __init__(self, run_folder: Path) -> None:
        self.run_folder = run_folder

    def write(self, column: str, point: int, value: object) -> str:
        """The relative file name of the frame ``value`` of ``column`` at communication point
        ``point``, written (empty when there is no frame)."""
        image = read_image(value) if isinstance(value, bytes) else None
        if image is None:
            return ""
        encoded = png(image)
        name = f"{FOLDER}/{column}/{point:06d}.{'bin' if encoded is None else 'png'}"
        path = self.run_folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(image.data if encoded is None else encoded)
        return name
