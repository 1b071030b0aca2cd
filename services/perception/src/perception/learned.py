"""The learned detector's pixel model: which pixels are a balise's, learned from frames the
OpenRails mock rendered under many conditions and their labels (``scripts/train-balise-model.py``,
``make detector-model``), in place of the colour detector's fixed thresholds.

A pixel's features (``candidates``) are its colour and its colour against its row's median --
the ballast, sleepers and air at that distance: fog adds the same airlight to a whole row and
night darkens it, so what stays of a balise under them is how it differs from its row. The
model is a decision tree over those features (scikit-learn's ``DecisionTreeClassifier``,
depth 10, balanced classes, a fixed seed); a pixel whose leaf's probability is at least
``cut`` is a balise's. The rest -- blobs, distance,
range, bound -- is the colour detector's (``detector.find`` with this mask).

The model file is JSON (tens of kB: the tree's nodes, the cut, how it was trained and
validated): read with numpy alone, no pickle. At inference one compiled pass (``pixels``,
numba, IEEE float32 in numpy's order) gives each pixel's probability, the values numpy's
step-by-step path (``probability_numpy``) gives; the same frame gives the same mask on every
machine.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

Pixels = npt.NDArray[np.uint8]
FEATURES = ("r", "g", "b", "r-b", "g-b", "dr", "dg", "db", "dr-db", "dg-db", "hue")
"""Per pixel (0..1 scale): its colour, two chromas, the same against its row's median, and the
row-relative chroma over the row-relative brightness change (hue of the difference)."""


def candidates(rgb: Pixels) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float32]]:
    """The pixels that lean towards yellow against their row (red and green above the row's
    median by more than blue is) -- the only ones the model judges -- as flat indices, and a
    row of ``FEATURES`` for each."""
    pixels = rgb.astype(np.float32) / 255.0
    diff = pixels - np.median(pixels, axis=1, keepdims=True)
    lean = (diff[..., 0] > diff[..., 2]) & (diff[..., 1] > diff[..., 2])
    index = np.flatnonzero(lean)
    flat, flat_diff = pixels.reshape(-1, 3)[index], diff.reshape(-1, 3)[index]
    r, g, b = flat[:, 0], flat[:, 1], flat[:, 2]
    dr, dg, db = flat_diff[:, 0], flat_diff[:, 1], flat_diff[:, 2]
    size = np.abs(dr) + np.abs(dg) + np.abs(db) + 0.03
    columns = [r, g, b, r - b, g - b, dr, dg, db, dr - db, dg - db, (dr + dg - 2 * db) / size]
    return index, np.stack(columns, axis=1)


@dataclass(frozen=True)
class PixelModel:
    """A decision tree over ``features`` (scikit-learn's, as arrays): node i tests
    ``feature[i] <= threshold[i]`` and goes to ``left[i]``, else ``right[i]``; a leaf (its
    children itself) holds the probability that its pixels are a balise's."""

    feature: npt.NDArray[np.int64]
    threshold: npt.NDArray[np.float32]
    left: npt.NDArray[np.int64]
    right: npt.NDArray[np.int64]
    probability_of: npt.NDArray[np.float32]
    depth: int
    cut: float = 0.5
    """A pixel is a balise's when its leaf's probability is at least this."""
    trained: dict[str, Any] | None = None
    """How it was trained and what it scored on held-out frames (the model file's record)."""

    def probability(self, rgb: Pixels) -> npt.NDArray[np.float32]:
        """Each pixel's probability of being a balise's, in the frame's shape (0 where it is
        no candidate): ``probability_numpy``'s values, computed in one compiled pass
        (``pixels``)."""
        from . import pixels  # numba: imported where a run asks for the learned detector

        return pixels.frame_probability(
            rgb, self.feature, self.threshold, self.left, self.right, self.probability_of,
            self.depth,
        )  # fmt: skip

    def probability_numpy(self, rgb: Pixels) -> npt.NDArray[np.float32]:
        """``probability`` in numpy, a step at a time: ``candidates``, ``predict``, ``scatter``
        (what the training script computes; the compiled pass is held to it)."""
        index, x = candidates(rgb)
        return self.scatter(rgb, index, self.predict(x))

    def predict(self, x: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """The probability of each row of features."""
        rows = np.arange(len(x))
        node = np.zeros(len(x), dtype=np.int64)
        for _ in range(self.depth):
            go_left = x[rows, self.feature[node]] <= self.threshold[node]
            node = np.where(go_left, self.left[node], self.right[node])
        return self.probability_of[node]

    @staticmethod
    def scatter(
        rgb: Pixels, index: npt.NDArray[np.int64], values: npt.NDArray[np.float32]
    ) -> npt.NDArray[np.float32]:
        out = np.zeros(rgb.shape[0] * rgb.shape[1], dtype=np.float32)
        out[index] = values
        return out.reshape(rgb.shape[:2])

    def mask(self, rgb: Pixels) -> npt.NDArray[np.bool_]:
        """Balise pixels: probability at least ``cut``."""
        return self.probability(rgb) >= self.cut

    def to_json(self) -> str:
        return json.dumps(
            {
                "model": "decision tree over perception.learned.features (scikit-learn)",
                "features": list(FEATURES),
                "depth": self.depth,
                "cut": self.cut,
                "trained": self.trained or {},
                "nodes": {
                    "feature": self.feature.tolist(),
                    "threshold": [float(v) for v in self.threshold],
                    "left": self.left.tolist(),
                    "right": self.right.tolist(),
                    "probability": [round(float(v), 6) for v in self.probability_of],
                },
            },
            separators=(",", ":"),
        )

    @classmethod
    def load(cls, path: Path) -> PixelModel:
        """The model in ``path``; ModelError naming the file and the fix."""
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            if data.get("features") != list(FEATURES):
                raise ModelError(
                    f"model file {path} was trained on features {data.get('features')}, "
                    f"this detector computes {list(FEATURES)}: train it again "
                    f"(make detector-model)"
                )
            nodes = data["nodes"]
            feature, left, right = (np.asarray(nodes[k], dtype=np.int64)
                                    for k in ("feature", "left", "right"))  # fmt: skip
            threshold = np.asarray(nodes["threshold"], dtype=np.float32)
            probability = np.asarray(nodes["probability"], dtype=np.float32)
            count = len(feature)
            if any(len(a) != count for a in (threshold, left, right, probability)) or not (
                count and (feature >= 0).all() and (feature < len(FEATURES)).all()
                and (left >= 0).all() and (left < count).all()
                and (right >= 0).all() and (right < count).all()
            ):  # fmt: skip
                raise ModelError(f"model file {path}: its nodes are not a tree of {FEATURES}")
            return cls(feature, threshold, left, right, probability, int(data["depth"]),
                       float(data["cut"]), data.get("trained"))  # fmt: skip
        except FileNotFoundError:
            raise ModelError(
                f"model file {path} does not exist: make detector-model writes it (or give "
                f"the perception service --model FILE)"
            ) from None
        except (OSError, ValueError, KeyError, TypeError) as exc:
            if isinstance(exc, ModelError):
                raise
            raise ModelError(f"model file {path} cannot be read: {exc}") from None


class ModelError(ValueError):
    """A model file that is missing, unreadable or of other features."""
