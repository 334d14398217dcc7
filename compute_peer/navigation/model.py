"""What both planners share: the vehicle, the result, and the checks on start, goal and path."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .costmap import Costmap, path_collision
from .errors import NavigationError
from .geometry import wrap_angle
from .grid import dilate

PLANNERS = ("hybrid_astar", "ompl", "ompl:rrtstar", "ompl:bitstar")  # "ompl": the configured OMPL planner


@dataclass(frozen=True, slots=True)
class VehicleModel:
    """A car-like robot: a disk of ``robot_radius`` that cannot turn tighter than ``turning_radius``.

    With ``allow_reverse`` it may also drive backwards (Reeds-Shepp instead of Dubins motion).
    """

    robot_radius: float = 0.25
    turning_radius: float = 0.5
    allow_reverse: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.robot_radius) and self.robot_radius >= 0):
            raise NavigationError(f"robot radius must be >= 0, got {self.robot_radius}")
        if not (math.isfinite(self.turning_radius) and self.turning_radius > 0):
            raise NavigationError(f"turning radius must be > 0, got {self.turning_radius}")


@dataclass(frozen=True, slots=True, eq=False)
class PlanResult:
    """A path (poses at most one map cell apart), who planned it, how long it took, how long it is; ``note``:
    what was done to a start or goal near an obstacle (:mod:`.recovery`), "" when nothing."""

    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    planner: str
    seconds: float
    length: float
    expansions: int = 0
    note: str = ""


Pose2 = tuple[float, float, float]


def as_pose(p, what: str) -> Pose2:
    try:
        vals = [float(v) for v in p]
    except (TypeError, ValueError):
        raise NavigationError(f"{what} must be (x, y, theta), got {p!r}") from None
    if len(vals) != 3:
        raise NavigationError(f"{what} must be (x, y, theta), got {len(vals)} values")
    if not all(math.isfinite(v) for v in vals):
        raise NavigationError(f"{what} must be finite, got {tuple(vals)}")
    return vals[0], vals[1], float(wrap_angle(vals[2]))


def check_endpoints(costmap: Costmap, start: Pose2, goal: Pose2) -> "Tight":
    """Refuse a start or goal outside the map or where the robot would not fit, saying which and why.

    A start or goal where the robot fits but inside the planners' margin (a robot parked close to a
    wall) is accepted; the returned :class:`Tight` tells the planners to check motions near it densely.
    """
    if not costmap.blocked.size or costmap.collision.all():
        raise NavigationError(
            "the map has no free space for the robot (empty map, or everything within the robot radius of an obstacle)"
        )
    for pose, what in ((goal, "goal"), (start, "start")):
        reason = costmap.clearance_reason(pose[0], pose[1], what, tight_ok=True)
        if reason is not None:
            raise NavigationError(reason)
    tight = tuple((p[0], p[1]) for p in (start, goal) if not costmap.free_xy(p[0], p[1]))
    return Tight(costmap, tight)


class Tight:
    """Endpoints inside the margin, and the dense check that lets motions near them through.

    Near such an endpoint (within ``reach``) a motion that fails the cheap check against ``blocked`` is
    accepted when it passes the contract itself: dense sampling (a quarter cell) against ``collision``.
    """

    def __init__(self, costmap: Costmap, points: tuple[tuple[float, float], ...], reach: float = 1.0) -> None:
        self.costmap = costmap
        self.points = points
        self.reach = reach + costmap.robot_radius + costmap.margin
        self._half: np.ndarray | None = None

    def __bool__(self) -> bool:
        return bool(self.points)

    def near(self, x: float, y: float) -> bool:
        return any(math.hypot(x - px, y - py) <= self.reach for px, py in self.points)

    def motion_ok(self, x: np.ndarray, y: np.ndarray) -> bool:
        """Dense check of a polyline that starts and ends near a tight endpoint."""
        return (
            bool(self.points)
            and self.near(float(x[0]), float(y[0]))
            and self.near(float(x[-1]), float(y[-1]))
            and (path_collision(self.costmap, x, y) is None)
        )

    def state_ok(self, x: float, y: float) -> bool:
        """For OMPL's validity callback: near a tight endpoint and clear of obstacles by radius + half a cell."""
        if not self.points or not self.near(x, y):
            return False
        cm = self.costmap
        if self._half is None:
            self._half = dilate(cm.occupied, cm.robot_radius / cm.resolution + 0.5)
        h, w = self._half.shape
        c = math.floor((x - cm.origin_x) / cm.resolution)
        r = math.floor((y - cm.origin_y) / cm.resolution)
        if not (0 <= c < w and 0 <= r < h):
            return False
        if not self._half[r, c]:
            return True
        # the endpoint's own cell (the robot is there already) only has to be clear of the radius
        return not cm.collision[r, c] and any(
            math.floor((px - cm.origin_x) / cm.resolution) == c and math.floor((py - cm.origin_y) / cm.resolution) == r
            for px, py in self.points
        )


def path_length(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.hypot(np.diff(x), np.diff(y)).sum()) if len(x) > 1 else 0.0


def finish(costmap: Costmap, x, y, theta, *, planner: str, seconds: float, expansions: int = 0) -> PlanResult:
    """Check the path against the collision map by dense sampling, then wrap it up."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    theta = wrap_angle(np.asarray(theta, dtype=np.float64))
    bad = path_collision(costmap, x, y)
    if bad is not None:
        raise NavigationError(f"{planner} produced a path that touches an obstacle (sample {bad}); refusing it")
    return PlanResult(x, y, theta, planner, seconds, path_length(x, y), expansions)
