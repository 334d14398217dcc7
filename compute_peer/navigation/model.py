"""What both planners share: the vehicle, the result, and the checks on start, goal and path."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .costmap import Costmap, path_collision
from .errors import NavigationError
from .geometry import wrap_angle

PLANNERS = ("hybrid_astar", "ompl")


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
    """A path (poses at most one map cell apart), who planned it, how long it took, how long it is."""

    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    planner: str
    seconds: float
    length: float
    expansions: int = 0


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


def check_endpoints(costmap: Costmap, start: Pose2, goal: Pose2) -> None:
    """Refuse a start or goal outside the map or where the robot would not fit, saying which and why."""
    if not costmap.blocked.size or costmap.blocked.all():
        raise NavigationError("the map has no free space for the robot (empty map, or everything within the robot radius of an obstacle)")
    for pose, what in ((goal, "goal"), (start, "start")):
        reason = costmap.clearance_reason(pose[0], pose[1], what)
        if reason is not None:
            raise NavigationError(reason)


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
