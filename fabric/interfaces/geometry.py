"""Angle and orientation helpers shared by every peer (pure; numpy arrays or plain floats).

One definition each, so that a sim's controller, the navigation planner, the path follower and the
user's views agree on where an angle wraps (``[-pi, pi)``) and on what a heading is. Quaternions are
(w, x, y, z), the order of every fabric message (:class:`~fabric.interfaces.std.Pose`) and of MuJoCo;
the frames of the world are right-handed with z up, headings (yaw) about z.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["TWO_PI", "wrap_angle", "yaw_from_quaternion", "quaternion_from_yaw"]

TWO_PI = 2.0 * math.pi


def wrap_angle(a: Any) -> Any:
    """Angle(s) wrapped to [-pi, pi); an array is wrapped element-wise, a scalar stays a scalar."""
    return (np.asarray(a) + math.pi) % TWO_PI - math.pi if isinstance(a, np.ndarray) else (a + math.pi) % TWO_PI - math.pi


def yaw_from_quaternion(q: Any) -> float:
    """Heading (rad, about z) of a (w, x, y, z) quaternion; a tilted one gives its heading's projection."""
    w, x, y, z = (float(v) for v in q)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_from_yaw(yaw: float) -> np.ndarray:
    """The (w, x, y, z) quaternion of a rotation by ``yaw`` (rad) about z."""
    return np.array([math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)])
