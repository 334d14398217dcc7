"""Latency compensation (paper Eq. 8): a remote pose seen ``age`` seconds ago moved on by velocity * age."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["extrapolate", "age_s"]


def age_s(stamp_wall_ns: int, now_wall_ns: int, *, cap_s: float = 0.2) -> float:
    """Age of a message from its header wall time, clamped to [0, cap_s] (clock skew, stale streams)."""
    return float(min(max((now_wall_ns - stamp_wall_ns) * 1e-9, 0.0), cap_s))


def extrapolate(position: ArrayLike, velocity: ArrayLike, age: float, *, cap_s: float = 0.2) -> np.ndarray:
    """``position + velocity * min(age, cap_s)``; a negative age counts as zero. Why capped: a stale
    message must not fling a remote robot across the room."""
    a = min(max(float(age), 0.0), cap_s)
    return np.asarray(position, dtype=float) + np.asarray(velocity, dtype=float) * a
