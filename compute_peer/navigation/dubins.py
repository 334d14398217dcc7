"""Dubins paths (shortest forward-only paths with a minimum turning radius), sampled in numpy.

Used by Hybrid A* for its analytic expansion ("shot") to the goal. The six
words LSL, RSR, LSR, RSL, RLR, LRL are solved in closed form (Shkel and
Lumelsky); every candidate is verified by integrating it to its end pose, so a
numerically degenerate word is dropped rather than returned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geometry import TWO_PI, arc, wrap_angle

_KAPPA = {"L": 1.0, "S": 0.0, "R": -1.0}


def _mod2pi(a: float) -> float:
    return a % TWO_PI


@dataclass(frozen=True, slots=True)
class DubinsPath:
    """Three segments: word like "LSR" and their lengths in metres."""

    word: str
    lengths: tuple[float, float, float]
    radius: float

    @property
    def length(self) -> float:
        return sum(self.lengths)

    def sample(self, x: float, y: float, th: float, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Poses from (x, y, th) along the path at most ``step`` apart, both ends included."""
        xs, ys, ts = [np.array([x])], [np.array([y])], [np.array([th])]
        for ch, seg in zip(self.word, self.lengths):
            if seg <= 1e-12:
                continue
            n = max(1, math.ceil(seg / step))
            s = np.linspace(seg / n, seg, n)
            k = _KAPPA[ch] / self.radius
            px, py, pt = arc(x, y, th, k, s)
            xs.append(px)
            ys.append(py)
            ts.append(pt)
            x, y, th = float(px[-1]), float(py[-1]), float(pt[-1])
        return np.concatenate(xs), np.concatenate(ys), np.concatenate(ts)

    def end(self, x: float, y: float, th: float) -> tuple[float, float, float]:
        """End pose after driving the path from (x, y, th) (scalar math: called for every candidate)."""
        for ch, seg in zip(self.word, self.lengths):
            k = _KAPPA[ch] / self.radius
            if k == 0.0:
                x, y = x + seg * math.cos(th), y + seg * math.sin(th)
            else:
                t2 = th + k * seg
                x, y, th = x + (math.sin(t2) - math.sin(th)) / k, y - (math.cos(t2) - math.cos(th)) / k, t2
        return x, y, th


def _words(d: float, a: float, b: float) -> list[tuple[str, float, float, float]]:
    sa, sb, ca, cb = math.sin(a), math.sin(b), math.cos(a), math.cos(b)
    cab = math.cos(a - b)
    out = []
    p2 = 2 + d * d - 2 * cab + 2 * d * (sa - sb)
    if p2 >= 0:
        tmp = math.atan2(cb - ca, d + sa - sb)
        out.append(("LSL", _mod2pi(-a + tmp), math.sqrt(p2), _mod2pi(b - tmp)))
    p2 = 2 + d * d - 2 * cab + 2 * d * (sb - sa)
    if p2 >= 0:
        tmp = math.atan2(ca - cb, d - sa + sb)
        out.append(("RSR", _mod2pi(a - tmp), math.sqrt(p2), _mod2pi(-b + tmp)))
    p2 = -2 + d * d + 2 * cab + 2 * d * (sa + sb)
    if p2 >= 0:
        p = math.sqrt(p2)
        tmp = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        out.append(("LSR", _mod2pi(-a + tmp), p, _mod2pi(-_mod2pi(b) + tmp)))
    p2 = -2 + d * d + 2 * cab - 2 * d * (sa + sb)
    if p2 >= 0:
        p = math.sqrt(p2)
        tmp = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        out.append(("RSL", _mod2pi(a - tmp), p, _mod2pi(b - tmp)))
    tmp = (6.0 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8.0
    if abs(tmp) <= 1.0:
        p = _mod2pi(TWO_PI - math.acos(tmp))
        t = _mod2pi(a - math.atan2(ca - cb, d - sa + sb) + p / 2.0)
        out.append(("RLR", t, p, _mod2pi(a - b - t + p)))
    tmp = (6.0 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8.0
    if abs(tmp) <= 1.0:
        p = _mod2pi(TWO_PI - math.acos(tmp))
        t = _mod2pi(-a - math.atan2(ca - cb, d + sa - sb) + p / 2.0)
        out.append(("LRL", t, p, _mod2pi(_mod2pi(b) - a - t + p)))
    return out


def dubins_paths(
    start: tuple[float, float, float], goal: tuple[float, float, float], radius: float
) -> list[DubinsPath]:
    """All valid Dubins paths from ``start`` to ``goal``, shortest first."""
    x0, y0, t0 = start
    x1, y1, t1 = goal
    dx, dy = x1 - x0, y1 - y0
    d = math.hypot(dx, dy) / radius
    phi = math.atan2(dy, dx) if d > 1e-12 else 0.0
    a, b = _mod2pi(t0 - phi), _mod2pi(t1 - phi)
    tol = 1e-6 * max(1.0, radius)
    out = []
    for word, t, p, q in _words(d, a, b):
        path = DubinsPath(word, (t * radius, p * radius, q * radius), radius)
        ex, ey, et = path.end(x0, y0, t0)
        if abs(ex - x1) < tol * 10 and abs(ey - y1) < tol * 10 and abs(wrap_angle(et - t1)) < 1e-5:
            out.append(path)
    out.sort(key=lambda p: p.length)
    return out
