"""Angle and orientation helpers shared by every peer (pure; numpy arrays or plain floats).

One definition each, so that a sim's controller, the navigation planner, the path follower and the
user's views agree on where an angle wraps (``[-pi, pi)``; the closed-form IK asks for ``(-pi, pi]``) and on what a heading is. Quaternions are
(w, x, y, z), the order of every fabric message (:class:`~fabric.interfaces.std.Pose`) and of MuJoCo;
the frames of the world are right-handed with z up, headings (yaw) about z.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["TWO_PI", "wrap_angle", "yaw_from_quaternion", "quaternion_from_yaw"]

TWO_PI = 2.0 * math.pi


def wrap_angle(a: Any, *, include_pi: bool = False) -> Any:
    """Angle(s) wrapped to [-pi, pi); an array is wrapped element-wise, a scalar stays a scalar.

    ``include_pi=True`` wraps to (-pi, pi] instead, by the exact remainder (``fmod``): an angle already in
    range comes back unchanged, bit for bit. The closed-form IK asks for it: a half turn it adds (the other
    shoulder, the flipped wrist) lands on +pi, the upper limit of a joint that turns +-180 deg, and its
    solutions stay bit for bit what they were before this function was shared.
    """
    if include_pi:
        if a.__class__ is not float and isinstance(a, np.ndarray):  # floats first: ~14 wraps per closed-form solve
            r = np.fmod(a, TWO_PI)
            r = np.where(r > math.pi, r - TWO_PI, r)
            return np.where(r <= -math.pi, r + TWO_PI, r)
        a = math.fmod(a, TWO_PI)  # inline, not a helper call: the closed form's budget is ~50 us
        if a > math.pi:
            a -= TWO_PI
        elif a <= -math.pi:
            a += TWO_PI
        return a
    return (
        (np.asarray(a) + math.pi) % TWO_PI - math.pi if isinstance(a, np.ndarray) else (a + math.pi) % TWO_PI - math.pi
    )


def yaw_from_quaternion(q: Any) -> float:
    """Heading (rad, about z) of a (w, x, y, z) quaternion; a tilted one gives its heading's projection."""
    w, x, y, z = (float(v) for v in q)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_from_yaw(yaw: float) -> np.ndarray:
    """The (w, x, y, z) quaternion of a rotation by ``yaw`` (rad) about z."""
    return np.array([math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)])
