"""The second planner: OMPL 2 (new nanobind bindings) on a Dubins or Reeds-Shepp state space.

``DubinsStateSpace(R)`` when the robot only drives forwards, ``ReedsSheppStateSpace(R)``
when it may reverse; bounds are the map's extent. States are checked against the
costmap's ``blocked`` mask from a Python callback, and motions are checked by
OMPL at least once per map cell of path length (the validity resolution is set
from the space's maximum extent), which is what the costmap's margin assumes.

RRT* and BIT* are anytime planners: by default planning stops at the first
exact solution (or the time limit), the path is shortcut by OMPL's simplifier,
then interpolated to half a map cell between poses. OMPL's interpolation may
put a Reeds-Shepp cusp between two poses (Hybrid A* always has a pose on it). ``refine_time`` lets the
planner keep improving the solution for that long before stopping.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from .costmap import Costmap
from .errors import NavigationError
from .model import PlanResult, Pose2, VehicleModel, check_endpoints, finish

OMPL_PLANNERS = ("rrtstar", "bitstar")
RESTART_FIRST_SLICE = 0.5  # s: the first tree's time before a fresh one is tried (then 1, 2, 4 ... s)
FINISH_ATTEMPTS = 4  # paths finish() may refuse near a tight endpoint before the planner gives up

_quiet = threading.Lock()
_quieted = False


def _ompl():
    """Import OMPL lazily (it is a heavy import) and silence its info logging once."""
    global _quieted
    from ompl import base as ob, geometric as og, util as ou

    with _quiet:
        if not _quieted:
            ou.setLogLevel(ou.LogLevel.LOG_ERROR)  # RRT* warns that Dubins distance is asymmetric: known, harmless
            _quieted = True
    return ob, og


@dataclass(frozen=True, slots=True)
class OmplConfig:
    planner: str = "bitstar"  # RRT* on the asymmetric Dubins space has a long tail (docs/benchmarks/navigation.md)
    time_limit: float = 2.0  # seconds to find a first solution
    refine_time: float = 0.0  # extra seconds to improve it (anytime planners)
    simplify_time: float = 0.05
    goal_tolerance: float = 1e-3  # in the state space's distance (metres of Dubins/Reeds-Shepp length)

    def __post_init__(self) -> None:
        if self.planner not in OMPL_PLANNERS:
            raise NavigationError(f"unknown OMPL planner {self.planner!r}; expected one of {', '.join(OMPL_PLANNERS)}")
        if not (self.time_limit > 0 and self.refine_time >= 0 and self.simplify_time >= 0):
            raise NavigationError("OMPL needs time_limit > 0, refine_time >= 0 and simplify_time >= 0")


def plan_ompl(
    costmap: Costmap, start: Pose2, goal: Pose2, vehicle: VehicleModel | None = None, config: OmplConfig | None = None
) -> PlanResult:
    vehicle = vehicle or VehicleModel()
    cfg = config or OmplConfig()
    t0 = time.perf_counter()
    tight = check_endpoints(costmap, start, goal)
    ob, og = _ompl()
    space = (
        ob.ReedsSheppStateSpace(vehicle.turning_radius)
        if vehicle.allow_reverse
        else ob.DubinsStateSpace(vehicle.turning_radius)
    )
    x0, y0, x1, y1 = costmap.bounds
    bounds = ob.RealVectorBounds(2)
    bounds.setLow(0, x0)
    bounds.setHigh(0, x1)
    bounds.setLow(1, y0)
    bounds.setHigh(1, y1)
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)
    free_xy = costmap.free_xy
    if tight:
        tight_ok = tight.state_ok
        ss.setStateValidityChecker(lambda s: free_xy(s.getX(), s.getY()) or tight_ok(s.getX(), s.getY()))
    else:
        ss.setStateValidityChecker(lambda s: free_xy(s.getX(), s.getY()))
    si = ss.getSpaceInformation()
    si.setStateValidityCheckingResolution(0.9 * costmap.resolution / space.getMaximumExtent())
    s_state = space.allocState()
    s_state.setX(start[0])
    s_state.setY(start[1])
    s_state.setYaw(start[2])
    g_state = space.allocState()
    g_state.setX(goal[0])
    g_state.setY(goal[1])
    g_state.setYaw(goal[2])
    ss.setStartAndGoalStates(s_state, g_state, cfg.goal_tolerance)
    # an objective satisfied by any cost makes the anytime planners stop at their first solution
    objective = ob.PathLengthOptimizationObjective(si)
    objective.setCostThreshold(ob.Cost(math.inf))
    ss.setOptimizationObjective(objective)
    planner = og.RRTstar(si) if cfg.planner == "rrtstar" else og.BITstar(si)
    ss.setPlanner(planner)
    ss.setup()
    # A tree that starts badly (wedged in beside a wall) can take seconds where a fresh one takes
    # milliseconds: the time to a first solution has a heavy tail (40 tight Reeds-Shepp runs: median
    # 14 ms, worst 6.6 s; one CI run hit the 10 s limit). So the budget is spent in restarts with a fresh
    # tree, each slice twice the last, until time_limit is used up.
    # Near a tight endpoint states are checked without the full margin, so a path may also graze a
    # collision cell between two checked states: finish() refuses it, and OMPL tries afresh.
    # the budget is the search's: from here, not from t0 (OMPL's first import and the endpoints' check once took a
    # loaded box's whole 2 s, and the planner gave up before its first try: "no time to plan")
    deadline = time.perf_counter() + cfg.time_limit
    slice_s = min(cfg.time_limit, RESTART_FIRST_SLICE)
    refused = 0
    status = None
    while True:
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            raise NavigationError(
                f"OMPL {cfg.planner} found no path from ({start[0]:.2f}, {start[1]:.2f}) to ({goal[0]:.2f}, {goal[1]:.2f}) "
                f"within {cfg.time_limit:.2f} s ({status.asString() if status is not None else 'no time to plan'})"
            )
        status = ss.solve(min(slice_s, remaining))
        if ss.haveExactSolutionPath():
            if cfg.refine_time > 0:
                objective.setCostThreshold(ob.Cost(0.0))
                ss.solve(cfg.refine_time)
            if cfg.simplify_time > 0:
                ss.simplifySolution(cfg.simplify_time)
            xs, ys, ts = _states(ss.getSolutionPath(), costmap.resolution)
            xs[-1], ys[-1], ts[-1] = goal  # the goal state is reached within goal_tolerance: end exactly on it
            try:
                return finish(costmap, xs, ys, ts, planner=f"ompl:{cfg.planner}", seconds=time.perf_counter() - t0)
            except NavigationError:
                refused += 1
                if not tight or refused >= FINISH_ATTEMPTS:
                    raise
        else:
            slice_s *= 2
        ss.clear()
        objective.setCostThreshold(ob.Cost(math.inf))


def _states(path, resolution: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The solution interpolated to half a map cell between poses, as arrays."""
    n = max(2, math.ceil(path.length() / (0.5 * resolution)) + 1)
    path.interpolate(n)
    states = path.getStates()
    xs = np.fromiter((s.getX() for s in states), dtype=np.float64, count=len(states))
    ys = np.fromiter((s.getY() for s in states), dtype=np.float64, count=len(states))
    ts = np.fromiter((s.getYaw() for s in states), dtype=np.float64, count=len(states))
    return xs, ys, ts
