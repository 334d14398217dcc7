"""A synthetic world for tests and the benchmark: real fabric messages on real keys at default rates.

Each robot publishes joints (100 Hz, 6 joints), pose (50 Hz) and a 240-ray
scan (20 Hz), the sim peer's default streams. All streams share one absolute
schedule in one thread (a heap of due times), so a publisher of many robots
costs one thread, and its "sent" counts are exact for loss accounting.
"""

from __future__ import annotations

import heapq
import math
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from fabric import keys
from fabric.codec import encode
from fabric.interfaces import Header, JointState, Pose, Scan
from fabric.streams import default_rates

__all__ = ["LoadStream", "robot_streams", "run_load", "DEFAULT_RATES"]

DEFAULT_RATES = default_rates()
"""The sim's default rate of each stream group (:func:`fabric.streams.default_rates`), the load's streams."""
_JOINTS = tuple(f"joint{i}" for i in range(1, 7))


@dataclass(frozen=True, slots=True)
class LoadStream:
    key: str
    hz: float
    make: Callable[[int, float], bytes]  # (seq, t) -> payload


def _joints(source: str) -> Callable[[int, float], bytes]:
    def make(seq: int, t: float) -> bytes:
        q = np.sin(t + np.arange(6))
        return encode(JointState(_JOINTS, q, np.cos(t + np.arange(6)), Header(t, time.time_ns(), seq, source)))

    return make


def _pose(source: str) -> Callable[[int, float], bytes]:
    def make(seq: int, t: float) -> bytes:
        c, s = math.cos(t / 2), math.sin(t / 2)
        return encode(
            Pose(
                np.array([math.cos(t), math.sin(t), 0.0]),
                np.array([c, 0.0, 0.0, s]),
                header=Header(t, time.time_ns(), seq, source),
            )
        )

    return make


def _scan(source: str) -> Callable[[int, float], bytes]:
    rng = np.random.default_rng(abs(hash(source)) % (1 << 32))
    base = rng.random(240) * 8.0 + 0.5

    def make(seq: int, t: float) -> bytes:
        r = base + 0.05 * math.sin(t)
        return encode(
            Scan.from_ranges(
                r,
                angle_min=-math.pi,
                angle_increment=2 * math.pi / 240,
                range_max=12.0,
                header=Header(t, time.time_ns(), seq, source),
            )
        )

    return make


def _cycled(make: Callable[[int, float], bytes], n: int) -> Callable[[int, float], bytes]:
    payloads = [make(i, i * 0.01) for i in range(n)]
    return lambda seq, _t: payloads[seq % n]


def robot_streams(
    world: str,
    robots: int,
    *,
    scale: float = 1.0,
    rates: dict[str, float] | None = None,
    prefix: str = "r",
    precompute: int = 0,
) -> list[LoadStream]:
    """``robots`` robots x (joints, pose, scan) at ``rates`` (default rates) times ``scale``.

    ``precompute > 0`` cycles through that many pre-encoded payloads per stream instead of encoding
    each message: a publisher fast enough to find the recorder's ceiling rather than its own.
    """
    rates = {**DEFAULT_RATES, **(rates or {})}
    makers = {"joints": _joints, "pose": _pose, "scan": _scan}
    out = []
    for i in range(robots):
        rid = f"{prefix}{i}"
        for stream, hz in rates.items():
            make = makers[stream](rid)
            out.append(
                LoadStream(
                    keys.robot_stream(world, rid, stream),
                    hz * scale,
                    _cycled(make, precompute) if precompute > 0 else make,
                )
            )
    return out


def run_load(
    put: Callable[[str, bytes], Any],
    streams: list[LoadStream],
    *,
    duration: float,
    stop: threading.Event | None = None,
) -> tuple[Counter[str], float]:
    """Publish every stream on its own absolute grid for ``duration`` s; returns (sent per key, elapsed s)."""
    stop = stop or threading.Event()
    t0 = time.perf_counter()
    heap = [(t0 + (j / len(streams)) / s.hz, j, 0) for j, s in enumerate(streams)]  # stagger starts
    heapq.heapify(heap)
    sent: Counter[str] = Counter()
    end = t0 + duration
    while heap and not stop.is_set():
        due, j, seq = heap[0]
        if due >= end:
            break
        left = due - time.perf_counter()
        if left > 0.0005:
            time.sleep(left - 0.0003)
            continue
        heapq.heappop(heap)
        s = streams[j]
        put(s.key, s.make(seq, due - t0))
        sent[s.key] += 1
        heapq.heappush(heap, (t0 + (seq + 1 + j / len(streams)) / s.hz, j, seq + 1))
    return sent, time.perf_counter() - t0
