"""Planar pose helpers shared by mapping and planning (pure numpy)."""

from __future__ import annotations

from typing import Any

import numpy as np

from fabric.interfaces import TWO_PI, wrap_angle

__all__ = ["TWO_PI", "wrap_angle"]  # re-exported: the planners import them from here


def arc(x0: Any, y0: Any, th0: Any, kappa: float, s: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses after driving signed arc length ``s`` (negative = reverse) at curvature ``kappa``.

    Exact for circles and straight lines, vectorised over ``s`` (and broadcast over the start).
    """
    s = np.asarray(s, dtype=np.float64)
    th = th0 + kappa * s
    if abs(kappa) < 1e-12:
        return x0 + s * np.cos(th0), y0 + s * np.sin(th0), th + 0.0 * s
    return x0 + (np.sin(th) - np.sin(th0)) / kappa, y0 - (np.cos(th) - np.cos(th0)) / kappa, th
