"""Step latencies in constant memory (a log-bucketed histogram): a run of a million steps costs
what a run of ten does. A batch's buckets are counted in C where coupler-native is installed
(``coupler_native._rows.log_buckets``), else by its Python twin ``log_buckets``: the same
``native.BucketCount``, the same buckets (``tests/test_twins.py``)."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence

from coupler_orchestrator.native import BucketCount, rows


def log_buckets(
    samples: Sequence[float], floor: float, per_bucket: float, base: float
) -> tuple[float, float, Counter[int]]:
    """``BucketCount`` in Python (``coupler_native._rows.log_buckets``' twin)."""
    log = math.log
    total = 0.0
    for s in samples:  # in order, as C sums them (sum() may compensate)
        total += s
    counts = Counter(  # Counter counts an iterable in C
        [int((log(s) - floor) * per_bucket) if s > base else 0 for s in samples]
    )
    return total, max(samples), counts


class LatencyStats:
    """Step latencies in constant memory: count, sum, max, and a histogram of log buckets 1 %
    wide from 100 ns up, which gives any percentile within 1 %."""

    _BASE = 1e-7
    _WIDTH = math.log1p(0.01)

    def __init__(self) -> None:
        self.count = 0
        self.total = 0.0
        self.maximum = 0.0
        self._buckets: Counter[int] = Counter()

    def add_all(self, samples: Sequence[float]) -> None:
        """Count a batch of samples (one call per batch: the step loop's samples are folded in
        every ``SummaryWriter.BATCH`` steps)."""
        if not samples:
            return
        base = self._BASE
        native = rows()
        count: BucketCount = native.log_buckets if native is not None else log_buckets
        listed = samples if type(samples) is list else list(samples)
        total, maximum, counts = count(listed, math.log(base), 1 / self._WIDTH, base)
        self.count += len(samples)
        self.total += total
        self.maximum = max(self.maximum, maximum)
        self._buckets.update(counts)

    def percentile(self, q: float) -> float:
        """The ``q`` quantile (0..1) [s], within 1 %."""
        rank = q * (self.count - 1)
        seen = 0
        for bucket in sorted(self._buckets):
            seen += self._buckets[bucket]
            if seen > rank:
                return min(self._BASE * math.exp((bucket + 0.5) * self._WIDTH), self.maximum)
        return self.maximum

    def summary_ms(self) -> dict[str, float] | None:
        if not self.count:
            return None
        return {
            "mean": round(self.total / self.count * 1e3, 4),
            "p50": round(self.percentile(0.5) * 1e3, 4),
            "p99": round(self.percentile(0.99) * 1e3, 4),
            "max": round(self.maximum * 1e3, 4),
        }
