"""Starts and goals near obstacles recover, as Nav2's planners do (pure: costmap and poses in, poses out).

A robot stands where it stands: a base parked 0.2 m from a shelf, whose radius is 0.3 m, is "within the robot
radius of an obstacle", and a plan that refused to start there would leave the student stuck. So a start inside
the inflation (clear of the obstacles themselves) is planned from after a short **escape move**: a straight
drive of at most :data:`ESCAPE` metres, in the direction that gets the robot clear soonest, along which it never
comes nearer to any obstacle than it already is (the base turns on the spot first: its footprint is a disk about
its turn point). When no such move exists the start is refused, naming the obstacle that is in the way.

A goal clicked inside an obstacle, or too close to one for the robot, is moved to the nearest pose where the
robot fits (same heading), within :data:`GOAL_TOLERANCE` metres (Nav2's NavFn ``tolerance``), and the reply says
so; farther than that it is refused saying so. Each recovery is one sentence in :attr:`Recovery.notes`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .costmap import Costmap
from .errors import NavigationError

__all__ = ["ESCAPE", "GOAL_TOLERANCE", "Recovery", "RecoverySettings", "nearest_obstacle", "recover"]

ESCAPE = 0.5
"""The longest escape move from a start inside the inflation, in metres."""
GOAL_TOLERANCE = 0.5
"""How far a goal inside an obstacle may be moved to where the robot fits, in metres."""
DIRECTIONS = 32  # escape directions tried, evenly around the robot

Pose2 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class RecoverySettings:
    """How far a start may escape and a goal be moved (0 turns either off: the old refusals), and whether a base
    stuck at its start's heading may turn on the spot first."""

    escape: float = ESCAPE
    goal_tolerance: float = GOAL_TOLERANCE
    turn_in_place: bool = True  # the base turns about its footprint's centre (a differential drive): see plan_path


@dataclass(frozen=True, slots=True, eq=False)
class Recovery:
    """The poses to plan between, the escape move to drive first (x, y, theta; empty when none), and what was
    done, one sentence each."""

    start: Pose2
    goal: Pose2
    escape: tuple[np.ndarray, np.ndarray, np.ndarray] = field(
        default_factory=lambda: (np.zeros(0), np.zeros(0), np.zeros(0))
    )
    notes: tuple[str, ...] = ()


def nearest_obstacle(costmap: Costmap, x: float, y: float, within: float) -> tuple[float, float, float] | None:
    """(x, y, distance) of the centre of the obstacle cell nearest to (x, y) within ``within`` m, else None.

    An obstacle cell is one of the costmap's ``occupied`` (occupied, or unknown when unknown counts)."""
    res = costmap.resolution
    h, w = costmap.shape
    c0, r0 = math.floor((x - within - costmap.origin_x) / res), math.floor((y - within - costmap.origin_y) / res)
    c1, r1 = (
        math.floor((x + within - costmap.origin_x) / res) + 1,
        math.floor((y + within - costmap.origin_y) / res) + 1,
    )
    c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, w), min(r1, h)
    if c0 >= c1 or r0 >= r1:
        return None
    rows, cols = np.nonzero(costmap.occupied[r0:r1, c0:c1])
    if rows.size == 0:
        return None
    ox = costmap.origin_x + (cols + c0 + 0.5) * res
    oy = costmap.origin_y + (rows + r0 + 0.5) * res
    d = np.hypot(ox - x, oy - y)
    k = int(np.argmin(d))
    return (float(ox[k]), float(oy[k]), float(d[k])) if d[k] <= within else None


def _obstacles_near(costmap: Costmap, x: float, y: float, within: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the obstacle cells within a square of half-side ``within`` around (x, y)."""
    res = costmap.resolution
    h, w = costmap.shape
    c0 = max(math.floor((x - within - costmap.origin_x) / res), 0)
    r0 = max(math.floor((y - within - costmap.origin_y) / res), 0)
    c1 = min(math.floor((x + within - costmap.origin_x) / res) + 1, w)
    r1 = min(math.floor((y + within - costmap.origin_y) / res) + 1, h)
    rows, cols = np.nonzero(costmap.occupied[r0:r1, c0:c1])
    return costmap.origin_x + (cols + c0 + 0.5) * res, costmap.origin_y + (rows + r0 + 0.5) * res


def _escape(costmap: Costmap, start: Pose2, escape: float) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The shortest straight move from ``start`` to a strictly free cell (outside ``blocked``) within ``escape`` m
    along which the robot never comes nearer to an obstacle than it is at the start; (xs, ys, heading) or None."""
    x, y = start[0], start[1]
    step = costmap.resolution / 4.0
    ox, oy = _obstacles_near(costmap, x, y, escape + costmap.robot_radius + costmap.margin + costmap.resolution)
    here = float(np.hypot(ox - x, oy - y).min()) if ox.size else math.inf
    ks = np.arange(1, int(math.floor(escape / step)) + 1) * step
    best: tuple[np.ndarray, np.ndarray, float] | None = None
    for phi in np.linspace(-math.pi, math.pi, DIRECTIONS, endpoint=False):
        xs, ys = x + ks * math.cos(phi), y + ks * math.sin(phi)
        clear = (
            np.hypot(xs[:, None] - ox[None, :], ys[:, None] - oy[None, :]).min(axis=1)
            if ox.size
            else np.full(ks.size, math.inf)
        )
        nearer = np.flatnonzero(clear < here - 1e-9)
        free = np.flatnonzero(costmap.free(xs, ys))
        if free.size == 0:
            continue
        end = int(free[0])
        if nearer.size and nearer[0] <= end:
            continue
        if best is None or end + 1 < best[0].size:
            best = (np.concatenate([[x], xs[: end + 1]]), np.concatenate([[y], ys[: end + 1]]), float(phi))
    return best


def _free_goal(costmap: Costmap, goal: Pose2, tolerance: float) -> tuple[float, float] | None:
    """The centre of the strictly free cell (outside ``blocked``) nearest to the goal within ``tolerance``."""
    res = costmap.resolution
    h, w = costmap.shape
    gx, gy = goal[0], goal[1]
    c0 = max(math.floor((gx - tolerance - costmap.origin_x) / res), 0)
    r0 = max(math.floor((gy - tolerance - costmap.origin_y) / res), 0)
    c1 = min(math.floor((gx + tolerance - costmap.origin_x) / res) + 1, w)
    r1 = min(math.floor((gy + tolerance - costmap.origin_y) / res) + 1, h)
    if c0 >= c1 or r0 >= r1:
        return None
    rows, cols = np.nonzero(~costmap.blocked[r0:r1, c0:c1])
    if rows.size == 0:
        return None
    fx = costmap.origin_x + (cols + c0 + 0.5) * res
    fy = costmap.origin_y + (rows + r0 + 0.5) * res
    d = np.hypot(fx - gx, fy - gy)
    k = int(np.argmin(d))
    return (float(fx[k]), float(fy[k])) if d[k] <= tolerance else None


def _obstacle_words(costmap: Costmap, x: float, y: float) -> str:
    hit = nearest_obstacle(costmap, x, y, costmap.robot_radius + costmap.margin + costmap.resolution)
    if hit is None:
        return "an obstacle"
    return f"an obstacle or unknown space at ({hit[0]:.2f}, {hit[1]:.2f}), {hit[2]:.2f} m away"


def recover(costmap: Costmap, start: Pose2, goal: Pose2, settings: RecoverySettings | None = None) -> Recovery:
    """Where to plan from and to: ``start`` and ``goal`` as they are when the robot fits at both, else an escape
    move from a start inside the inflation and a goal moved out of an obstacle. NavigationError, naming the
    obstacle, when neither works (a start or goal outside the map is left to the planners' own refusal)."""
    s = settings or RecoverySettings()
    if not costmap.blocked.size or costmap.collision.all():
        return Recovery(start, goal)  # no free space at all: the planners say so
    notes: list[str] = []
    escape = (np.zeros(0), np.zeros(0), np.zeros(0))
    new_goal = goal
    if (
        costmap.inside(goal[0], goal[1])
        and costmap.clearance_reason(goal[0], goal[1], "goal", tight_ok=True) is not None
    ):
        why = costmap.clearance_reason(goal[0], goal[1], "goal", tight_ok=True)
        moved = _free_goal(costmap, goal, s.goal_tolerance) if s.goal_tolerance > 0 else None
        if moved is None:
            which = "" if "inside" in why else f" ({_obstacle_words(costmap, goal[0], goal[1])})"
            raise NavigationError(
                f"{why}{which}, and no pose where the robot fits lies within {s.goal_tolerance:.2f} m "
                f"of it: pick a goal in open floor"
            )
        new_goal = (moved[0], moved[1], goal[2])
        notes.append(
            f"goal moved {math.hypot(moved[0] - goal[0], moved[1] - goal[1]):.2f} m from ({goal[0]:.2f}, "
            f"{goal[1]:.2f}) to ({moved[0]:.2f}, {moved[1]:.2f}): it was {why.split(') is ', 1)[-1]}"
        )
    new_start = start
    sx, sy = start[0], start[1]
    if costmap.inside(sx, sy):
        r, c, _ = costmap.cells(np.array([sx]), np.array([sy]))
        if costmap.collision[r[0], c[0]] and not costmap.occupied[r[0], c[0]]:
            found = _escape(costmap, start, s.escape) if s.escape > 0 else None
            if found is None:
                raise NavigationError(
                    f"start ({sx:.2f}, {sy:.2f}) is within the robot radius ({costmap.robot_radius:.2f} m) of "
                    f"{_obstacle_words(costmap, sx, sy)}, and no straight move of up to {s.escape:.2f} m gets the "
                    f"robot clear without coming nearer to it: drive it clear first"
                )
            xs, ys, phi = found
            escape = (xs, ys, np.full(xs.size, phi))
            new_start = (float(xs[-1]), float(ys[-1]), phi)
            notes.append(
                f"start ({sx:.2f}, {sy:.2f}) is within the robot radius of {_obstacle_words(costmap, sx, sy)}: "
                f"the path first drives {math.hypot(xs[-1] - sx, ys[-1] - sy):.2f} m straight away from it"
            )
    return Recovery(new_start, new_goal, escape, tuple(notes))
