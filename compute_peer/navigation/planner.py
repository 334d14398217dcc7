"""One entry point for planning: pick the planner by name, check the request, return a PlanResult."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from fabric.interfaces import OccupancyGrid

from .costmap import Costmap, build_costmap
from .errors import NavigationError, StuckAtStart
from .geometry import wrap_angle
from .hybrid_astar import HybridAStarConfig, plan_hybrid_astar
from .model import PLANNERS, PlanResult, VehicleModel, as_pose, path_length
from .ompl_planner import OmplConfig, plan_ompl
from .recovery import Recovery, RecoverySettings, recover


@dataclass(frozen=True, slots=True)
class PlannerSettings:
    """Everything that shapes a plan besides the map, start and goal."""

    vehicle: VehicleModel = field(default_factory=VehicleModel)
    hybrid: HybridAStarConfig = field(default_factory=HybridAStarConfig)
    ompl: OmplConfig = field(default_factory=OmplConfig)
    threshold: int = 50  # map cells >= this percent are obstacles
    unknown_is_occupied: bool = True
    recovery: RecoverySettings = field(default_factory=RecoverySettings)  # starts and goals near obstacles


def plan_path(
    world_map: OccupancyGrid | Costmap,
    start,
    goal,
    *,
    planner: str = "hybrid_astar",
    settings: PlannerSettings | None = None,
) -> PlanResult:
    """Plan from ``start`` to ``goal`` (each (x, y, theta)) on a map or a prepared costmap.

    ``planner``: "hybrid_astar", "ompl" (the OMPL planner of ``settings.ompl``), "ompl:rrtstar" or "ompl:bitstar".
    """
    settings = settings or PlannerSettings()
    if planner not in PLANNERS:
        raise NavigationError(f"unknown planner {planner!r}; expected one of {', '.join(PLANNERS)}")
    s = as_pose(start, "start")
    g = as_pose(goal, "goal")
    if isinstance(world_map, Costmap):
        costmap = world_map
    else:
        costmap = build_costmap(
            world_map,
            settings.vehicle.robot_radius,
            threshold=settings.threshold,
            unknown_is_occupied=settings.unknown_is_occupied,
        )
    rec = recover(costmap, s, g, settings.recovery)
    if planner == "hybrid_astar":
        result = _hybrid(costmap, rec, settings)
    else:
        ompl = settings.ompl
        if ":" in planner:
            ompl = replace(ompl, planner=planner.split(":", 1)[1])
        result = plan_ompl(costmap, rec.start, rec.goal, settings.vehicle, ompl)
    if not rec.notes and not result.note:
        return result
    ex, ey, et = rec.escape
    if ex.size:  # the escape move, then the plan from where it ends
        x, y, theta = (np.concatenate([e[:-1], r]) for e, r in ((ex, result.x), (ey, result.y), (et, result.theta)))
        result = replace(result, x=x, y=y, theta=theta, length=path_length(x, y))
    return replace(result, note="; ".join([*rec.notes, *([result.note] if result.note else [])]))


TURNS = tuple(math.radians(a) for a in (90, -90, 135, -135, 180))
"""Headings (from the start's) a base stuck at its start may turn to on the spot before it drives: at least 90
degrees, so that the sim's follower turns on the spot (beyond 60 degrees) rather than swinging an arc."""


def _hybrid(costmap: Costmap, rec: Recovery, settings: PlannerSettings) -> PlanResult:
    """Hybrid A* from ``rec.start``; when every first arc from its heading touches an obstacle and the base turns
    on the spot (``settings.recovery.turn_in_place``), from the same place facing another way (:data:`TURNS`),
    the result's note saying so. The base's footprint is a disk about its turn point: turning never touches."""
    try:
        return plan_hybrid_astar(costmap, rec.start, rec.goal, settings.vehicle, settings.hybrid)
    except StuckAtStart as stuck:
        if not settings.recovery.turn_in_place:
            raise
        x, y, th = rec.start
        # the turns share one plan's time: the service plans one at a time, and others wait behind this one
        share = replace(settings.hybrid, time_limit=settings.hybrid.time_limit / len(TURNS))
        for turn in TURNS:
            facing = float(wrap_angle(th + turn))
            try:
                result = plan_hybrid_astar(costmap, (x, y, facing), rec.goal, settings.vehicle, share)
            except NavigationError:
                continue
            return replace(
                result,
                note=f"it cannot drive away facing {math.degrees(th):.0f} deg, so it first turns on the "
                f"spot to {math.degrees(facing):.0f} deg",
            )
        raise stuck
