"""Pure pursuit along a path, with in-place turns at cusps and where the path bends back, and a final heading.

A stretch between cusps whose headings point against its direction of travel (a reversing plan) is driven
backwards: the same law for the base turned around. Otherwise the robot faces its direction of travel (as the
real Reeman does): when the
lookahead point is far off to the side it turns on the spot first, then drives.
The path is split at its cusps (vertices where the direction changes by more
than ``turn_in_place``); the base slows down to stop at each cusp
(v = sqrt(2 a d)), turns on the spot, and goes on. At the end it turns to the
path's last heading. The progress index only moves within a short stretch of arc
length, so a path that crosses or doubles back on itself is never shortcut.
Inputs and outputs are plain numbers.
"""

from __future__ import annotations

import math

import numpy as np

from fabric.interfaces import wrap_angle
from sim_peer.controllers import CommandRejected


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
        headings = np.asarray(theta, dtype=np.float64) if theta is not None and len(theta) == len(pts) else None
        self.final_yaw = float(headings[-1]) if headings is not None else None
        keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9])
        pts = pts[keep]  # repeated points have no direction
        self.points = pts
        seg = np.diff(pts, axis=0)
        self.cumulative = np.concatenate([[0.0], np.cumsum(np.linalg.norm(seg, axis=1))])
        heading = np.arctan2(seg[:, 1], seg[:, 0])
        bend = np.abs(wrap_angle(np.diff(heading)))
        cusps = [int(i) + 1 for i in np.flatnonzero(bend > turn_in_place)]
        self.stops = [*cusps, len(pts) - 1]  # vertices to stop at: cusps, then the end
        # a stretch is driven backwards when the path's headings point against its direction of travel (a
        # reversing plan: the Path message has no direction field, the headings say it)
        self.backwards = [False] * len(self.stops)
        if headings is not None and len(pts) > 1:
            facing = np.cos(heading - headings[keep][1:])  # each segment's travel against the heading at its end
            starts = [0, *self.stops[:-1]]
            self.backwards = [bool(facing[a:b].sum() < 0) if b > a else False for a, b in zip(starts, self.stops)]
        self.stretch = 0
        self.max_speed, self.max_omega, self.max_accel = max_speed, max_omega, max_accel
        self.lookahead = lookahead
        self.goal_tolerance = goal_tolerance
        self.yaw_tolerance = yaw_tolerance
        self.turn_in_place = turn_in_place
        self.index = 0
        self.arrived = False
        self.done = False

    def _advance(self, p: np.ndarray, stop: int) -> None:
        """Move the progress index to the nearest point within the next stretch of arc length, not past ``stop``."""
        reach = self.cumulative[self.index] + max(self.lookahead, 0.3)
        end = min(stop + 1, max(self.index + 1, int(np.searchsorted(self.cumulative, reach, side="right"))))
        d = np.linalg.norm(self.points[self.index : end] - p, axis=1)
        self.index += int(np.argmin(d))

    def _reached(self, p: np.ndarray, stop: int, yaw: float, v: float) -> bool:
        along = self.cumulative[stop] - self.cumulative[self.index]
        if along > self.lookahead:
            return False
        d = float(np.linalg.norm(self.points[stop] - p))
        if d < self.goal_tolerance:
            return True
        if self.index == stop and d < 4 * self.goal_tolerance:
            # at rest next to it, or already past it (it lies behind): good enough, no circling back
            dx, dy = self.points[stop] - p
            behind = dx * math.cos(yaw) + dy * math.sin(yaw) < 0
            return abs(v) < 0.02 or behind
        return False

    def step(self, x: float, y: float, yaw: float, v: float, dt: float) -> tuple[float, float, bool]:
        if self.done:
            return 0.0, 0.0, True
        if not self.arrived and self.backwards[self.stretch]:
            # backwards: the same law for a base facing the other way (its heading turned around, its speed
            # negated), whose twist is the real base's with the speed negated back
            v_d, w_d, done = self._drive(x, y, wrap_angle(yaw + math.pi), -v)
            return -v_d, w_d, done
        return self._drive(x, y, yaw, v)

    def _drive(self, x: float, y: float, yaw: float, v: float) -> tuple[float, float, bool]:
        p = np.array([x, y])
        while not self.arrived:
            stop = self.stops[self.stretch]
            self._advance(p, stop)
            if self._reached(p, stop, yaw, v):
                if self.stretch == len(self.stops) - 1:
                    self.arrived = True
                    break
                self.stretch += 1  # a cusp: on to the next stretch (the base turns on the spot towards it)
                self.index = stop
                if self.backwards[self.stretch] != self.backwards[self.stretch - 1]:
                    return 0.0, 0.0, False  # it runs the other way: the next step drives it in its own frame
                continue
            to_stop = (
                self.cumulative[stop] - self.cumulative[self.index] + float(np.linalg.norm(self.points[self.index] - p))
            )
            # Lookahead: first point ahead of the progress index at least `lookahead` away, not past the stop.
            d = np.linalg.norm(self.points[self.index : stop + 1] - p, axis=1)
            ahead = np.flatnonzero(d >= self.lookahead)
            target = self.points[self.index + int(ahead[0])] if ahead.size else self.points[stop]
            dx, dy = target - p
            c, s = math.cos(yaw), math.sin(yaw)
            lx, ly = c * dx + s * dy, -s * dx + c * dy
            alpha = math.atan2(ly, lx)
            ld = max(math.hypot(lx, ly), 1e-6)
            if abs(alpha) > self.turn_in_place:
                return 0.0, math.copysign(self.max_omega, alpha) * min(1.0, abs(alpha)), False
            v_d = min(self.max_speed, math.sqrt(2 * self.max_accel * 0.8 * max(to_stop, 0.0)))
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
