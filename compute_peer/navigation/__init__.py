"""Mapping and navigation for the compute peer: the paper's Test B.

Pure cores (no Zenoh): :mod:`.mapping` (log-odds occupancy from scans),
:mod:`.mapio` (PGM + YAML like ROS map_server, NPZ), :mod:`.costmap` (obstacle
inflation), :mod:`.hybrid_astar` and :mod:`.ompl_planner` (the two planners,
chosen through :func:`plan_path`). :mod:`.service` serves them over the fabric:
``register_navigation(fabric)`` declares ``srv/map/**`` and ``srv/plan/**``.
The service names are loaded lazily so that importing the pure parts never
imports zenoh. The services' requests and replies are in :mod:`fabric.interfaces.navigation`.
"""

from typing import Any

from .costmap import Costmap, build_costmap, path_collision
from .errors import NavigationError
from .hybrid_astar import HybridAStar, HybridAStarConfig, plan_hybrid_astar
from .mapio import load_map, load_npz, load_pgm_yaml, save_map, save_npz, save_pgm_yaml
from .mapping import MapperConfig, OccupancyMapper
from .model import PlanResult, VehicleModel
from .ompl_planner import OmplConfig, plan_ompl
from .planner import PlannerSettings, plan_path

__all__ = [
    "Costmap",
    "HybridAStar",
    "HybridAStarConfig",
    "MapperConfig",
    "NavigationError",
    "NavigationService",
    "OccupancyMapper",
    "OmplConfig",
    "PlanResult",
    "PlannerSettings",
    "VehicleModel",
    "build_costmap",
    "load_map",
    "load_npz",
    "load_pgm_yaml",
    "path_collision",
    "plan_hybrid_astar",
    "plan_ompl",
    "plan_path",
    "register_navigation",
    "save_map",
    "save_npz",
    "save_pgm_yaml",
]


def __getattr__(name: str) -> Any:
    if name in ("NavigationService", "register_navigation"):
        from . import service

        return getattr(service, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
