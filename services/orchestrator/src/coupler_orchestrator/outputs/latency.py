"""Step latencies in constant memory (a log-bucketed histogram): a run of a million steps costs
what a run of ten does. A batch's buckets are counted in C where coupler-native is installed
(``coupler_native._rows.log_buckets``: the same buckets, ``tests/test_latency.py``)."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence

from coupler_orchestrator.native import rows


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
        log, base = math.log, self._BASE
        floor, per_bucket = log(base), 1 / self._WIDTH
        native = rows()
        if native is not None and type(samples) is list:
            total, maximum, counts = native.log_buckets(samples, floor, per_bucket, base)
            self.count += len(samples)
            self.total += total
            self.maximum = max(self.maximum, maximum)
            self._buckets.update(counts)
            return
        self.count += len(samples)
        self.total += sum(samples)
        self.maximum = max(self.maximum, *samples)
        self._buckets.update(  # Counter counts an iterable in C
            [int((log(s) - floor) * per_bucket) if s > base else 0 for s in samples]
        )

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
