"""Planar angle helpers shared by every peer (pure; numpy arrays or plain floats).

One definition, so that a sim's controller, the navigation planner and the
path follower agree on where an angle wraps: ``[-pi, pi)``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

TWO_PI = 2.0 * math.pi


def wrap_angle(a: Any) -> Any:
    """Angle(s) wrapped to [-pi, pi); an array is wrapped element-wise, a scalar stays a scalar."""
    return (np.asarray(a) + math.pi) % TWO_PI - math.pi if isinstance(a, np.ndarray) else (a + math.pi) % TWO_PI - math.pi
