"""Running statistics of one stream: rate, interval jitter, bandwidth, latency percentiles."""

from __future__ import annotations

from collections import deque

import numpy as np


class StreamStats:
    """Arrival times and sizes of one key; ``summary()`` gives rate, jitter (std of intervals) and bytes/s."""

    def __init__(self, window: int = 10_000) -> None:
        self.count = 0
        self.bytes = 0
        self.first: float | None = None
        self.last: float | None = None
        self.intervals: deque[float] = deque(maxlen=window)

    def add(self, t: float, size: int) -> None:
        if self.last is not None:
            self.intervals.append(t - self.last)
        if self.first is None:
            self.first = t
        self.last = t
        self.count += 1
        self.bytes += size

    def summary(self) -> dict:
        span = (self.last - self.first) if self.first is not None and self.last is not None else 0.0
        iv = np.asarray(self.intervals, dtype=np.float64)
        return {
            "count": self.count,
            "bytes": self.bytes,
            "rate_hz": (self.count - 1) / span if span > 0 else 0.0,
            "jitter_ms": float(iv.std() * 1e3) if iv.size else 0.0,
            "min_ms": float(iv.min() * 1e3) if iv.size else 0.0,
            "max_ms": float(iv.max() * 1e3) if iv.size else 0.0,
            "bytes_per_s": self.bytes / span if span > 0 else 0.0,
        }


def percentiles(values, ps=(50, 90, 99, 100)) -> dict[str, float]:
    """``{"p50": ..., "p99": ...}`` of ``values`` (empty -> NaN)."""
    arr = np.asarray(list(values), dtype=np.float64)
    if arr.size == 0:
        return {f"p{p}": float("nan") for p in ps}
    return {f"p{p}": float(np.percentile(arr, p)) for p in ps}
