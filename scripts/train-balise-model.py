"""Train the learned balise detector's pixel model (services/perception, ``detector = learned``)
on frames the OpenRails mock's renderer draws under varied conditions, with their labels.

    .venv/bin/python scripts/train-balise-model.py --out build/models/balise-pixels.json
    (make detector-model)

The training set: camera places 6 to 38 m before the balise groups from 4 km on along the
Annaberg-Schwarzenberg line (never the first 2.4 km, where the perception campaign runs), each
under conditions drawn with a fixed seed (time of day 06:00-23:30 with the sun of the place and
the headlights, fog visibility 8 m to clear, snow cover and dirt 0 to 0.95, rain, autumn
leaves, sensor noise). Every third group is held out for validation. A pixel is a positive when
it lies in a balise's labelled box (``ObjectLabel.box``, balises 5-40 m ahead); negatives are
drawn from the rest of the frame. Only candidate pixels (``perception.learned.candidates``) are
learned from and judged. Trained with scikit-learn's DecisionTreeClassifier (depth 10,
balanced classes, random_state 0): the same script on the same machine writes the same file.

Printed and written into the model file (``trained``): the split, the pixels, and on the held-out
frames the pixel precision/recall and the share of balises (5-40 m ahead, at least 4 pixels
visible) that a blob of the mask touches -- for the learned mask and the colour detector's.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage
from sklearn.tree import DecisionTreeClassifier

from coupler_railway import load_infrastructure
from openrails_mock.conditions import Conditions
from openrails_mock.renderer import CameraModel, Frame, Renderer, View
from openrails_mock.scene import Scene
from perception.detector import yellow_mask
from perception.learned import FEATURES, PixelModel, candidates

ROOT = Path(__file__).resolve().parents[1]
RAILML = ROOT / "scenarios" / "railway" / "data" / "annaberg-schwarzenberg.railml"
FROM_M = 4000.0
"""Balise groups before this distance are the campaign's stretch: never trained on."""
DEPTH = 10
SEED = 40
CUT = 0.9
"""A pixel is a balise's at this leaf probability: at 0.5 the mask finds a few more balises but
makes ten times the false blobs (set by looking at frames of the campaign's stretch, so not
independent of the campaign)."""
NEGATIVES = 6000
"""Negative pixels drawn per frame."""


def draw_conditions(rng: np.random.Generator) -> tuple[dict[str, Any], float]:
    """One draw of the world: conditions and the hour."""
    hour = float(rng.choice([6.5, 9.0, 12.0, 15.0, 18.0, 20.5, 22.0, 23.5]))
    conditions: dict[str, Any] = {"light": "sun", "seed": int(rng.integers(1, 10_000))}
    if rng.random() < 0.6:
        conditions["visibility_m"] = float(rng.choice([8.0, 12.0, 18.0, 25.0, 35.0, 50.0, 80.0]))
    if rng.random() < 0.4:
        conditions["snow_cover"] = float(rng.uniform(0.2, 0.95))
    if rng.random() < 0.4:
        conditions["dirt"] = float(rng.uniform(0.2, 0.95))
    if rng.random() < 0.15:
        conditions["weather"] = "rain"
    if rng.random() < 0.15:
        conditions["season"] = "autumn"
    if rng.random() < 0.3:
        conditions["noise"] = True
    return conditions, hour


def samples(
    frame: Frame, rng: np.random.Generator, negatives: int
) -> tuple[np.ndarray, np.ndarray]:
    """Features and labels (1: a balise's pixel) of a frame's candidate pixels: every positive,
    ``negatives`` negatives drawn."""
    index, x = candidates(frame.pixels)
    truth = truth_mask(frame).ravel()[index]
    positive = np.flatnonzero(truth)
    negative = np.flatnonzero(~truth)
    if len(negative) > negatives:
        negative = np.sort(rng.choice(negative, negatives, replace=False))
    chosen = np.concatenate([positive, negative])
    return x[chosen], truth[chosen].astype(np.int8)


def truth_mask(frame: Frame) -> np.ndarray:
    """The labelled boxes of the balises 5-40 m ahead."""
    mask = np.zeros(frame.pixels.shape[:2], dtype=bool)
    for label in shown(frame):
        left, top, right, bottom = label.box
        mask[top : bottom + 1, left : right + 1] = True
    return mask


def shown(frame: Frame) -> list[Any]:
    return [
        x
        for x in frame.labels
        if x.kind == "balise" and x.pixels >= 4 and 5.0 <= x.distance_along_m <= 40.0
    ]


def found_share(frames: list[Frame], masks: list[np.ndarray]) -> tuple[int, int]:
    """Balises shown whose box a blob of the mask (2 pixels or more) touches, and how many."""
    hit = total = 0
    for frame, mask in zip(frames, masks, strict=True):
        labels, _ = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
        sizes = np.bincount(labels.ravel())
        for label in shown(frame):
            left, top, right, bottom = label.box
            ids = np.unique(labels[top : bottom + 1, left : right + 1])
            total += 1
            hit += any(i and sizes[i] >= 2 for i in ids)
    return hit, total


def pixel_scores(frames: list[Frame], masks: list[np.ndarray]) -> dict[str, float]:
    tp = fp = fn = 0
    for frame, mask in zip(frames, masks, strict=True):
        truth = truth_mask(frame)
        tp += int((mask & truth).sum())
        fp += int((mask & ~truth).sum())
        fn += int((~mask & truth).sum())
    return {
        "pixel_precision": round(tp / max(tp + fp, 1), 4),
        "pixel_recall": round(tp / max(tp + fn, 1), 4),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=ROOT / "build" / "models" / "balise-pixels.json"
    )
    parser.add_argument("--draws", type=int, default=4, help="condition draws per place")
    args = parser.parse_args()
    started = time.monotonic()
    infrastructure = load_infrastructure(RAILML)
    scene = Scene.of_infrastructure(infrastructure)
    camera = CameraModel(width=800, height=600, fov_deg=45.0)
    firsts: dict[int, float] = {}
    for balise in sorted(infrastructure.balises, key=lambda b: b.distance_m):
        if balise.distance_m >= FROM_M:
            firsts.setdefault(balise.group, balise.distance_m)
    groups = sorted(firsts.items(), key=lambda g: g[1])
    rng = np.random.default_rng(SEED)
    split: dict[str, list[Frame]] = {"train": [], "validation": []}
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    for n, (_, first) in enumerate(groups):
        part = "validation" if n % 3 == 2 else "train"
        for _ in range(args.draws):
            conditions, hour = draw_conditions(rng)
            ahead = float(rng.uniform(6.0, 38.0))
            renderer = Renderer(scene, conditions=Conditions(**conditions))
            view = View(elapsed_s=1.0, clock_s=hour * 3600.0, speed_mps=15.0)
            frame = renderer.render(camera, first - ahead, view)
            split[part].append(frame)
            if part == "train":
                x, y = samples(frame, rng, NEGATIVES)
                xs.append(x)
                ys.append(y)
    x_train, y_train = np.concatenate(xs), np.concatenate(ys)
    tree = DecisionTreeClassifier(max_depth=DEPTH, class_weight="balanced", random_state=0)
    tree.fit(x_train, y_train)
    t = tree.tree_
    leaf = t.children_left < 0
    nodes = np.arange(t.node_count)
    # scikit-learn's value: per node the (weighted) class shares; the probability of class 1
    value = t.value[:, 0, :]
    probability = (value[:, 1] / value.sum(axis=1)).astype(np.float32)
    model = PixelModel(
        feature=np.where(leaf, 0, t.feature).astype(np.int64),
        threshold=np.where(leaf, 0.0, t.threshold).astype(np.float32),
        left=np.where(leaf, nodes, t.children_left).astype(np.int64),
        right=np.where(leaf, nodes, t.children_right).astype(np.int64),
        probability_of=probability,
        depth=int(tree.get_depth()),
        cut=CUT,
    )
    held_out = split["validation"]
    learned_masks = [model.mask(f.pixels) for f in held_out]
    colour_masks = [yellow_mask(f.pixels) for f in held_out]
    learned_hit, total = found_share(held_out, learned_masks)
    colour_hit, _ = found_share(held_out, colour_masks)
    record = {
        "script": "scripts/train-balise-model.py",
        "seed": SEED,
        "features": list(FEATURES),
        "frames": {k: len(v) for k, v in split.items()},
        "pixels": {"train": len(y_train), "train_positive": int(y_train.sum())},
        "validation": {
            "learned": {**pixel_scores(held_out, learned_masks),
                        "balises_touched": learned_hit, "balises": total},
            "colour": {**pixel_scores(held_out, colour_masks),
                       "balises_touched": colour_hit, "balises": total},
        },
    }  # fmt: skip
    model = PixelModel(**{**model.__dict__, "trained": record})
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(model.to_json(), encoding="utf-8")
    print(f"{args.out}: a tree of {t.node_count} nodes (depth {model.depth}) from "
          f"{len(y_train)} pixels ({int(y_train.sum())} a balise's) of {len(split['train'])} "
          f"frames, {time.monotonic() - started:.0f} s")  # fmt: skip
    for name, scores in record["validation"].items():  # type: ignore[union-attr]
        print(f"validation ({len(held_out)} frames), {name}: pixel precision "
              f"{scores['pixel_precision']}, pixel recall {scores['pixel_recall']}, balises "
              f"touched {scores['balises_touched']}/{scores['balises']}")  # fmt: skip


if __name__ == "__main__":
    main()
