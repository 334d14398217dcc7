"""Request and reply messages of the compute peer's ``map`` and ``plan`` services.

``rf/{world}/srv/map/{name}`` takes a :class:`MapRequest` and answers a :class:`MapReply`;
``rf/{world}/srv/plan/{robot}`` takes a :class:`PlanRequest` and answers a :class:`PlanReply`.
Optional poses are arrays of length 0 (absent) or 3 (x, y, theta); NaN and infinities are refused by
the decoder before a handler sees them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from fabric.codec import Arr, F, I, Msg, S, Spec, register
from fabric.interfaces._arrays import vector
from fabric.interfaces.std import HEADER, Header, OccupancyGrid, Path, new_header

__all__ = [
    "PlanRequest",
    "PlanReply",
    "MapRequest",
    "MapReply",
    "MAP_ACTIONS",
    "PLANNER_NAMES",
    "DIRECTIONS",
    "empty_grid",
]

PLANNER_NAMES = ("hybrid_astar", "ompl", "ompl:rrtstar", "ompl:bitstar")
DIRECTIONS = ("default", "forward", "both")
MAP_ACTIONS = ("start", "stop", "build", "get", "reset", "save", "load", "set", "status")


def empty_grid() -> OccupancyGrid:
    """The "no grid" value of MapRequest.grid / MapReply.grid: zero cells."""
    return OccupancyGrid(1.0, np.zeros(3), np.zeros((0, 0), dtype=np.uint8))


@dataclass(frozen=True, slots=True)
class PlanRequest:
    """Plan a path for ``robot``.

    ``goal``: (x, y, theta), or empty to use the goal object's pose; ``start``: (x, y, theta), or
    empty to use the robot's latest pose. ``planner``: hybrid_astar, ompl (the service's OMPL planner),
    ompl:rrtstar or ompl:bitstar. ``direction``: forward only, both (reversing allowed) or the
    service's default. ``turning_radius`` / ``robot_radius``: 0 means the service's default.
    """

    robot: str
    goal: np.ndarray = field(default_factory=lambda: np.zeros(0))
    start: np.ndarray = field(default_factory=lambda: np.zeros(0))
    planner: str = "hybrid_astar"
    map: str = "map"
    direction: str = "default"
    turning_radius: float = 0.0
    robot_radius: float = 0.0
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "robot": S(nonempty=True, max_len=200),
        "goal": Arr(np.float64, ndim=1),
        "start": Arr(np.float64, ndim=1),
        "planner": S(choices=PLANNER_NAMES),
        "map": S(nonempty=True, max_len=200),
        "direction": S(choices=DIRECTIONS),
        "turning_radius": F(lo=0.0, hi=100.0),
        "robot_radius": F(lo=0.0, hi=100.0),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "goal", vector(self.goal))
        object.__setattr__(self, "start", vector(self.start))

    def check(self) -> None:
        for name in ("goal", "start"):
            n = getattr(self, name).shape[0]
            if n not in (0, 3):
                raise ValueError(f"PlanRequest.{name} must be empty or (x, y, theta), got {n} values")


@dataclass(frozen=True, slots=True)
class PlanReply:
    """The planned path (also published on the robot's path key) and how it was obtained; ``note``: what the
    planner did to a start or goal near an obstacle (an escape move first, a goal moved), "" when nothing."""

    path: Path
    robot: str
    planner: str
    seconds: float
    length: float
    expansions: int = 0
    map: str = "map"
    header: Header = field(default_factory=new_header)
    note: str = ""

    SPEC: ClassVar[Spec] = {
        "path": Msg(Path),
        "robot": S(),
        "planner": S(),
        "seconds": F(lo=0.0),
        "length": F(lo=0.0),
        "expansions": I(lo=0),
        "map": S(),
        "header": HEADER,
        "note": S(),
    }
    OPTIONAL_TAIL: ClassVar[int] = 1  # note: added later, left off the wire when empty


@dataclass(frozen=True, slots=True)
class MapRequest:
    """Drive the mapping service.

    ``start``/``stop`` accumulating scans, ``build`` the binary map (cells with occupancy probability
    above ``threshold`` are occupied) and publish it, ``get`` it (or the live probability map if none
    was built), ``reset`` the accumulation, ``save``/``load`` it as ``file`` in the service's maps
    folder (``.npz``, else PGM + YAML), ``set`` it from ``grid``, or ask its ``status``.
    """

    action: str
    name: str = "map"
    threshold: float = 0.65
    file: str = ""
    grid: OccupancyGrid = field(default_factory=empty_grid)
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "action": S(choices=MAP_ACTIONS),
        "name": S(nonempty=True, max_len=200),
        "threshold": F(lo=0.0, hi=1.0),
        "file": S(max_len=255),
        "grid": Msg(OccupancyGrid),
        "header": HEADER,
    }


@dataclass(frozen=True, slots=True)
class MapReply:
    """What the map service did: the map (empty for status/start/stop), scans accumulated, mapping on/off."""

    action: str
    name: str
    grid: OccupancyGrid = field(default_factory=empty_grid)
    scans: int = 0
    mapping: int = 0
    file: str = ""
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "action": S(),
        "name": S(),
        "grid": Msg(OccupancyGrid),
        "scans": I(lo=0),
        "mapping": I(lo=0, hi=1),
        "file": S(),
        "header": HEADER,
    }


for _cls in (PlanRequest, PlanReply, MapRequest, MapReply):
    register(_cls)
