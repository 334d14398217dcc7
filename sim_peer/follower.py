"""Pure pursuit along a path, with in-place turns where the path bends back and a final heading.

The robot faces its direction of travel (as the real Reeman does): when the
lookahead point is far off to the side it turns on the spot first, then drives.
Speed ramps down so the base stops at the path's end (v = sqrt(2 a d)); then it
turns to the path's last heading. Inputs and outputs are plain numbers.
"""

from __future__ import annotations

import math

import numpy as np

from sim_peer.controllers import CommandRejected, wrap_angle


class PurePursuit:
    def __init__(
        self,
        x,
        y,
        theta=None,
        *,
        max_speed: float,
        max_omega: float,
        max_accel: float,
        lookahead: float = 0.5,
        goal_tolerance: float = 0.03,
        yaw_tolerance: float = 0.02,
        turn_in_place: float = math.radians(60),
    ) -> None:
        pts = np.column_stack([np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)])
        if pts.shape[0] == 0:
            raise CommandRejected("empty_path", "the path has no points")
        if not np.isfinite(pts).all():
            raise CommandRejected("not_finite", "the path contains NaN or infinity")
        if pts.shape[0] > 100_000:
            raise CommandRejected("path_too_long", f"the path has {pts.shape[0]} points (at most 100000)")
        self.points = pts
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        self.cumulative = np.concatenate([[0.0], np.cumsum(seg)])
        self.final_yaw = float(theta[-1]) if theta is not None and len(theta) == len(pts) else None
        self.max_speed, self.max_omega, self.max_accel = max_speed, max_omega, max_accel
        self.lookahead = lookahead
        self.goal_tolerance = goal_tolerance
        self.yaw_tolerance = yaw_tolerance
        self.turn_in_place = turn_in_place
        self.index = 0
        self.arrived = False
        self.done = False

    def _advance(self, p: np.ndarray) -> None:
        """Move the progress index forward to the nearest point within a short window (no shortcuts)."""
        end = min(len(self.points), self.index + 50)
        d = np.linalg.norm(self.points[self.index:end] - p, axis=1)
        self.index += int(np.argmin(d))

    def step(self, x: float, y: float, yaw: float, v: float, dt: float) -> tuple[float, float, bool]:
        if self.done:
            return 0.0, 0.0, True
        p = np.array([x, y])
        last = self.points[-1]
        if not self.arrived:
            self._advance(p)
            to_end = float(np.linalg.norm(last - p))
            remaining = self.cumulative[-1] - self.cumulative[self.index] + float(np.linalg.norm(self.points[self.index] - p))
            if to_end < self.goal_tolerance or (self.index == len(self.points) - 1 and to_end < 2 * self.goal_tolerance and abs(v) < 0.02):
                self.arrived = True
            else:
                # Lookahead: first point ahead of the progress index at least `lookahead` away, else the end.
                d = np.linalg.norm(self.points[self.index:] - p, axis=1)
                ahead = np.flatnonzero(d >= self.lookahead)
                target = self.points[self.index + int(ahead[0])] if ahead.size else last
                dx, dy = target - p
                c, s = math.cos(yaw), math.sin(yaw)
                lx, ly = c * dx + s * dy, -s * dx + c * dy
                alpha = math.atan2(ly, lx)
                ld = max(math.hypot(lx, ly), 1e-6)
                if abs(alpha) > self.turn_in_place:
                    return 0.0, math.copysign(self.max_omega, alpha) * min(1.0, abs(alpha)), False
                v_d = min(self.max_speed, math.sqrt(2 * self.max_accel * 0.8 * max(remaining, 0.0)))
                w_d = v_d * 2 * math.sin(alpha) / ld
                if abs(w_d) > self.max_omega:
                    v_d *= self.max_omega / abs(w_d)
                    w_d = math.copysign(self.max_omega, w_d)
                return v_d, w_d, False
        if self.final_yaw is None:
            self.done = True
            return 0.0, 0.0, True
        err = wrap_angle(self.final_yaw - yaw)
        if abs(err) < self.yaw_tolerance:
            self.done = True
            return 0.0, 0.0, True
        w = max(-self.max_omega, min(self.max_omega, 2.5 * err))
        if abs(w) < 0.1:
            w = math.copysign(0.1, err)
        return 0.0, w, False
