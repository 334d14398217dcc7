"""One entry point for planning: pick the planner by name, check the request, return a PlanResult."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from fabric.interfaces import OccupancyGrid

from .costmap import Costmap, build_costmap
from .errors import NavigationError
from .hybrid_astar import HybridAStarConfig, plan_hybrid_astar
from .model import PLANNERS, PlanResult, VehicleModel, as_pose
from .ompl_planner import OmplConfig, plan_ompl


@dataclass(frozen=True, slots=True)
class PlannerSettings:
    """Everything that shapes a plan besides the map, start and goal."""

    vehicle: VehicleModel = field(default_factory=VehicleModel)
    hybrid: HybridAStarConfig = field(default_factory=HybridAStarConfig)
    ompl: OmplConfig = field(default_factory=OmplConfig)
    threshold: int = 50  # map cells >= this percent are obstacles
    unknown_is_occupied: bool = True


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
    if planner == "hybrid_astar":
        return plan_hybrid_astar(costmap, s, g, settings.vehicle, settings.hybrid)
    ompl = settings.ompl
    if ":" in planner:
        ompl = replace(ompl, planner=planner.split(":", 1)[1])
    return plan_ompl(costmap, s, g, settings.vehicle, ompl)
