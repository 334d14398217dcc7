"""The planners' view of a map: obstacles inflated by the robot's radius.

Two inflated masks are kept. ``collision`` is the contract: a robot of radius
``r`` centred in a cell of it would touch an obstacle (cells whose centre lies
within ``r`` of an occupied cell's centre). ``blocked`` is what the planners
check, inflated by ``r + margin`` with ``margin = sqrt(2) * resolution``: a
planner that checks its path at least once per cell length against
``blocked`` yields a path of which *every* point - not only the checked ones -
lies outside ``collision`` (a point within half a cell of a checked point is at
most one cell away diagonally). :func:`path_collision` tests that contract by
dense sampling, and both planners run it on their result before returning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fabric.interfaces import OccupancyGrid

from .errors import NavigationError
from .grid import check_grid, dilate, occupied_mask


NEAR = 0.15
"""Metres beyond ``blocked`` where Hybrid A* charges extra (``HybridAStarConfig.near_penalty``), as Nav2's inflation
cost does: a path at the bare radius leaves a base's bumper no room (the Reeman's looks 4 cm past its radius ahead,
a wall's face lies up to half a cell nearer than its cell's centre, and the follower cuts a curve by up to 7 cm),
so two bases crossing in the shelves' gap each hugged a shelf's corner and met it on the bumper."""

MAX_INFLATION_CELLS = 250
"""The largest inflation, in cells, a costmap is built with: the inflation costs a pass per cell of radius (a 99 m
radius on a 5 cm map asked for 2,000 passes and several GB, and failed inside numpy)."""


@dataclass(frozen=True, eq=False)
class Costmap:
    resolution: float
    origin_x: float
    origin_y: float
    robot_radius: float
    margin: float
    occupied: np.ndarray  # (H, W) bool, the obstacles themselves (and unknown cells if they count)
    collision: np.ndarray  # (H, W) bool, inflated by robot_radius
    blocked: np.ndarray  # (H, W) bool, inflated by robot_radius + margin
    blocked_flat: bytes = field(repr=False, default=b"")  # one byte per cell, for scalar checks in callbacks
    near: np.ndarray | None = field(repr=False, default=None)  # (H, W) bool, within NEAR beyond ``blocked``

    def near_xy(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Per point: within :data:`NEAR` of ``blocked`` (free to drive, but where a planner had better not linger)."""
        if self.near is None:
            return np.zeros(np.shape(x), dtype=bool)
        r, c, inside = self.cells(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        return inside & self.near[r, c]

    @property
    def shape(self) -> tuple[int, int]:
        return self.blocked.shape  # type: ignore[return-value]

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        h, w = self.shape
        return self.origin_x, self.origin_y, self.origin_x + w * self.resolution, self.origin_y + h * self.resolution

    def cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        h, w = self.shape
        c = np.floor((x - self.origin_x) / self.resolution)
        r = np.floor((y - self.origin_y) / self.resolution)
        inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
        return np.clip(r, 0, h - 1).astype(np.intp), np.clip(c, 0, w - 1).astype(np.intp), inside

    def free(self, x: np.ndarray, y: np.ndarray, *, strict: bool = True) -> np.ndarray:
        """Per point: inside the map and not in ``blocked`` (``strict``) or not in ``collision``."""
        r, c, inside = self.cells(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        mask = self.blocked if strict else self.collision
        return inside & ~mask[r, c]

    def free_xy(self, x: float, y: float) -> bool:
        """Scalar strict check without numpy overhead (OMPL validity callbacks)."""
        h, w = self.blocked.shape
        c = math.floor((x - self.origin_x) / self.resolution)
        r = math.floor((y - self.origin_y) / self.resolution)
        return 0 <= c < w and 0 <= r < h and self.blocked_flat[r * w + c] == 0

    def inside(self, x: float, y: float) -> bool:
        x0, y0, x1, y1 = self.bounds
        return x0 <= x < x1 and y0 <= y < y1

    def clearance_reason(self, x: float, y: float, what: str, *, tight_ok: bool = False) -> str | None:
        """Why (x, y) cannot hold the robot, or None when it can.

        With ``tight_ok`` a point clear of ``collision`` but inside the margin is accepted.
        """
        if not self.inside(x, y):
            x0, y0, x1, y1 = self.bounds
            return f"{what} ({x:.2f}, {y:.2f}) is outside the map [{x0:.2f}, {x1:.2f}] x [{y0:.2f}, {y1:.2f}]"
        r, c, _ = self.cells(np.array([x]), np.array([y]))
        if self.occupied[r[0], c[0]]:
            return f"{what} ({x:.2f}, {y:.2f}) is inside an obstacle or unknown space"
        if self.collision[r[0], c[0]]:
            return f"{what} ({x:.2f}, {y:.2f}) is within the robot radius ({self.robot_radius:.2f} m) of an obstacle"
        if not tight_ok and not bool(self.free(np.array([x]), np.array([y]))[0]):
            return f"{what} ({x:.2f}, {y:.2f}) is closer than {self.robot_radius + self.margin:.2f} m to an obstacle (robot radius + margin)"
        return None


def build_costmap(
    grid: OccupancyGrid,
    robot_radius: float,
    *,
    threshold: int = 50,
    unknown_is_occupied: bool = True,
    margin: float | None = None,
) -> Costmap:
    """Inflate ``grid``'s obstacles (cells >= ``threshold`` percent, and unknown ones unless told otherwise)."""
    check_grid(grid)
    if not (robot_radius >= 0 and math.isfinite(robot_radius)):
        raise NavigationError(f"robot radius must be >= 0, got {robot_radius}")
    res = float(grid.resolution)
    margin = math.sqrt(2.0) * res if margin is None else float(margin)
    if (robot_radius + margin) / res > MAX_INFLATION_CELLS:  # checked before computing: the cost grows with it
        raise NavigationError(
            f"robot radius {robot_radius:.2f} m is {robot_radius / res:.0f} cells of this map ({res:.3f} m each): "
            f"at most {MAX_INFLATION_CELLS} cells ({MAX_INFLATION_CELLS * res - margin:.2f} m) are planned for"
        )
    occ = occupied_mask(grid, threshold, unknown_is_occupied=unknown_is_occupied)
    collision = dilate(occ, robot_radius / res)
    blocked = dilate(occ, (robot_radius + margin) / res)
    return Costmap(
        resolution=res,
        origin_x=float(grid.origin[0]),
        origin_y=float(grid.origin[1]),
        robot_radius=float(robot_radius),
        margin=margin,
        occupied=occ,
        collision=collision,
        blocked=blocked,
        blocked_flat=blocked.astype(np.uint8).tobytes(),
        near=dilate(occ, min((robot_radius + margin + NEAR) / res, MAX_INFLATION_CELLS)) & ~blocked,
    )


def densify(x: np.ndarray, y: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points along the polyline (x, y) at most ``step`` apart (vertices kept)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.size < 2:
        return x.copy(), y.copy()
    seg = np.hypot(np.diff(x), np.diff(y))
    n = np.maximum(1, np.ceil(seg / step).astype(np.intp))
    idx = np.repeat(np.arange(seg.size), n)
    frac = (np.arange(idx.size) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
    xs = x[idx] + frac * (x[idx + 1] - x[idx])
    ys = y[idx] + frac * (y[idx + 1] - y[idx])
    return np.append(xs, x[-1]), np.append(ys, y[-1])


def path_collision(costmap: Costmap, x: np.ndarray, y: np.ndarray, *, step: float | None = None) -> int | None:
    """Index of the first densely sampled point of the path inside ``collision`` (or outside the map), else None."""
    xs, ys = densify(x, y, step or costmap.resolution / 4.0)
    ok = costmap.free(xs, ys, strict=False)
    if ok.all():
        return None
    return int(np.flatnonzero(~ok)[0])
