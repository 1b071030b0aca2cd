"""The frames around every miss and every false detection of a perception run, kept while it
runs and drawn when it is scored.

**Kept** (``keeper``, the ``coupler.frames`` entry point the orchestrator calls at the start of
every run): in a run that records one camera frame column, a ``BaliseDetections`` column and a
TrackBalises ``passed_in_step`` column, the orchestrator keeps the ``BEFORE`` (10) frames
before and the ``AFTER`` (2) frames after every communication point where

- the perception reported a detection (it may turn out false: whether it is, is known only
  once the train has passed the place), or
- a balise was passed that no detection so far put within the gate of it (a miss: the frames
  before the pass show it coming).

So a run records the frames its report needs and not the others: in the 30-minute
Annaberg-Schwarzenberg run 631 of its 4,501 frames (211 points with detections, none
missed), one in seven.

**Drawn** (``draw``, by the scorer): for each miss the kept frames in which the balise was in
view before its pass, for each false detection the frame it was seen in, as PNG files in
``perception-frames/`` with the detector's boxes (green: matched to a balise, red: false) and
the ground truth's (blue, with the balise's id and true distance; ``camera.Camera``'s
flat-ground projection), linked from the report's rows. The kept frames are removed once drawn
(their ``index.json`` stays: the frames' camera, for scoring the run again).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from coupler.channels import Value
from coupler_railway.camera import Camera

BEFORE = 10
"""Frames kept before a point of interest: at 60 km/h and 0.4 s steps, 67 m of approach."""
AFTER = 2
"""Frames kept after it."""
KEPT = "kept-frames"
"""Where the orchestrator writes kept frames (``coupler_orchestrator.outputs.kept_frames``)."""
DRAWN = "perception-frames"
"""Where the drawn frames go in the run's folder."""
GATE_M = 1.5


@dataclass
class PerceptionKeeper:
    """What the orchestrator asks at every point (``coupler_orchestrator`` ``Keeper``)."""

    frames: str
    watches: tuple[str, str]
    """The detections column, the ``passed_in_step`` column."""
    before: int = BEFORE
    after: int = AFTER
    seen: list[float] = field(default_factory=list)
    """Track positions of every detection so far."""

    def wants(self, values: Sequence[Value]) -> bool:
        from coupler.v1.railway_pb2 import BaliseDetections

        found, passed = values
        positions: list[float] = []
        if isinstance(found, bytes) and found:
            message = BaliseDetections.FromString(found)
            positions = [d.track_position_m for d in message.detections]
            self.seen.extend(positions)
        missed = False
        for item in filter(None, str(passed or "").split(";")):
            distance = float(item.split(":")[2])
            missed |= not any(abs(p - distance) <= GATE_M for p in self.seen)
        return bool(positions) or missed


def keeper(columns: Mapping[str, str]) -> PerceptionKeeper | None:
    """The keeper of a perception run's frames; None for any other run."""
    from coupler_railway.messages import BALISE_DETECTIONS, IMAGE

    frames = [name for name, message in columns.items() if message == IMAGE]
    found = [name for name, message in columns.items() if message == BALISE_DETECTIONS]
    passed = [name for name in columns if name.endswith(".passed_in_step")]
    if len(frames) != 1 or len(found) != 1 or len(passed) != 1:
        return None
    return PerceptionKeeper(frames=frames[0], watches=(found[0], passed[0]))


@dataclass(frozen=True)
class KeptFrame:
    """One kept frame, as the orchestrator's ``index.json`` lists it."""

    path: Path
    point: int
    time: float
    """The communication point's time (the run's grid)."""
    camera: Camera


def kept_frames(folder: Path) -> list[KeptFrame]:
    """The frames kept in the run's ``folder`` (every frame column's), by point, with their
    camera mounted as the OpenRails mock mounts its sensors (``Camera``'s defaults): the truth,
    not what the perception participant was told. The index stays once the frames are drawn
    (``remove_kept``): a frame whose file is gone is listed too."""
    frames: list[KeptFrame] = []
    for index in sorted((folder / KEPT).glob("*/index.json")):
        for entry in json.loads(index.read_text(encoding="utf-8"))["frames"]:
            k = entry["intrinsics"]
            camera = Camera(
                width=int(entry["width"]),
                height=int(entry["height"]),
                fx=k["fx"],
                fy=k["fy"],
                cx=k["cx"],
                cy=k["cy"],
            )
            frames.append(
                KeptFrame(index.parent / entry["file"], entry["point"], entry["time"], camera)
            )
    return sorted(frames, key=lambda f: f.point)


@dataclass(frozen=True)
class Box:
    """A box drawn on a frame."""

    box: tuple[int, int, int, int]
    label: str
    kind: str
    """``true``, ``false`` (the detector's) or ``truth``."""


COLOURS = {"true": (40, 220, 60), "false": (255, 40, 40), "truth": (40, 140, 255)}


def draw(source: Path, target: Path, boxes: Sequence[Box], title: str) -> None:
    """``source`` with ``boxes`` drawn, a zoomed inset of where they are (bottom left: a
    balise 30 m ahead is a dozen pixels wide) and a title and legend line, written to
    ``target`` (PNG)."""
    from PIL import Image, ImageDraw

    with Image.open(source) as opened:
        picture = opened.convert("RGB")
    pen = ImageDraw.Draw(picture)
    for box in boxes:
        left, top, right, bottom = box.box
        pad = 2 if box.kind == "truth" else 0  # the truth's box around the detector's
        pen.rectangle((left - pad, top - pad, right + pad, bottom + pad), outline=COLOURS[box.kind])
    if boxes:
        margin = 24
        left = max(min(b.box[0] for b in boxes) - margin, 0)
        top = max(min(b.box[1] for b in boxes) - margin, 0)
        right = min(max(b.box[2] for b in boxes) + margin, picture.width - 1)
        bottom = min(max(b.box[3] for b in boxes) + margin, picture.height - 1)
        crop = picture.crop((left, top, right + 1, bottom + 1))
        fits = min((picture.width // 3) // crop.width, (picture.height // 2) // crop.height)
        scale = max(1, min(6, fits))
        inset = crop.resize((crop.width * scale, crop.height * scale), Image.Resampling.NEAREST)
        at = (4, picture.height - inset.height - 4)
        pen.rectangle((at[0] - 2, at[1] - 2, at[0] + inset.width + 1, at[1] + inset.height + 1),
                      fill=(255, 255, 255))  # fmt: skip
        picture.paste(inset, at)
    pen.rectangle((0, 0, picture.width, 15 + 12 * len(boxes)), fill=(0, 0, 0))
    pen.text((4, 2), title, fill=(255, 255, 255))
    for i, box in enumerate(boxes):
        kind = {"truth": "truth", "true": "detection", "false": "false detection"}[box.kind]
        pen.text((4, 15 + 12 * i), f"{kind}: {box.label}", fill=COLOURS[box.kind])
    target.parent.mkdir(parents=True, exist_ok=True)
    picture.save(target)


def remove_kept(folder: Path) -> None:
    """The kept frames, once drawn; their index stays (the frames' camera, for scoring the run
    again)."""
    for picture in (folder / KEPT).glob("*/*.png"):
        picture.unlink(missing_ok=True)
