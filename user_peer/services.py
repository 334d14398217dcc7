"""Calls to the services other peers serve: the sim's world description, the compute peer's IK, map and plan.

The message types belong to the peers that serve them (``sim_peer.messages``,
``compute_peer.messages``, ``compute_peer.navigation.messages``); this module
is the one place that builds their requests and reads their replies, so the
API above it deals only in numpy arrays and fabric messages.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from fabric import keys
from fabric.messages import OccupancyGrid, Path
from fabric.session import Fabric, ServiceError

__all__ = ["RobotEntry", "robot_entries", "world_info", "ik", "map_request", "build_map", "plan"]


def _module(name: str) -> Any:
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        raise ServiceError(f"{name} is not available in this installation ({exc})") from None


def _get(obj: Any, *names: str, default: Any = None) -> Any:
    for n in names:
        if hasattr(obj, n):
            return getattr(obj, n)
        if isinstance(obj, dict) and n in obj:
            return obj[n]
    return default


@dataclass(frozen=True, slots=True)
class RobotEntry:
    """One robot of a world, as the user API needs it."""

    id: str
    type: str
    kind: str
    joint_names: tuple[str, ...] = ()
    lower: tuple[float, ...] = ()
    upper: tuple[float, ...] = ()
    max_speed: tuple[float, ...] = ()


def robot_entries(info: Any) -> list[RobotEntry]:
    """Robots of a world description (``sim_peer.messages.WorldInfo``)."""
    return [
        RobotEntry(
            r.id, r.type, r.kind, tuple(r.joint_names),
            tuple(float(v) for v in r.lower), tuple(float(v) for v in r.upper), tuple(float(v) for v in r.max_speed),
        )
        for r in info.robots
    ]


def world_info(fab: Fabric, *, timeout: float = 5.0) -> Any:
    """The sim peer's world description (``rf/{world}/srv/world``)."""
    _module("sim_peer.messages")  # registers WorldInfo with the codec
    return fab.call(keys.srv(fab.world, "world"), timeout=timeout)


def _service_key(fab: Fabric, service: str, subject: str, peer: str | None) -> str:
    """``srv/{service}/{subject}``: the nearest compute peer; with ``peer``, that compute peer only."""
    return keys.srv(fab.world, service, subject) if peer is None else keys.srv(fab.world, service, subject, peer)


def ik(
    fab: Fabric, robot: str, xyz: Sequence[float], quaternion: Sequence[float] | None, seed: Any, *, timeout: float = 5.0, peer: str | None = None
) -> np.ndarray:
    """Joint angles for a flange position (world frame) from a compute peer (``peer``: a chosen one)."""
    m = _module("compute_peer.messages")
    req = m.IKRequest.make(xyz, quaternion, seed) if hasattr(m.IKRequest, "make") else m.IKRequest(
        np.asarray(xyz, dtype=float),
        np.asarray(quaternion if quaternion is not None else [], dtype=float),
        np.asarray(seed if seed is not None else [], dtype=float),
    )
    reply = fab.call(_service_key(fab, "ik", robot, peer), req, timeout=timeout)
    q = _get(reply, "q", "joints")
    if q is None:
        raise ServiceError(f"IK reply without joints: {reply!r}")
    return np.asarray(q, dtype=float)


def map_request(fab: Fabric, action: str, *, name: str = "map", threshold: float = 0.65, timeout: float = 10.0, peer: str | None = None) -> Any:
    """One request to the mapping service on ``rf/{world}/srv/map/{name}``; returns its MapReply."""
    m = _module("compute_peer.navigation.messages")
    return fab.call(_service_key(fab, "map", name, peer), m.MapRequest(action, name=name, threshold=threshold), timeout=timeout)


def build_map(fab: Fabric, *, name: str = "map", threshold: float = 0.65, timeout: float = 10.0, peer: str | None = None) -> OccupancyGrid:
    """Threshold the scans a compute peer accumulated into map ``name`` (also published on ``map/{name}``)."""
    reply = map_request(fab, "build", name=name, threshold=threshold, timeout=timeout, peer=peer)
    grid = reply.grid
    if not isinstance(grid, OccupancyGrid) or grid.cells.size == 0:
        raise ServiceError(f"the map service built no grid for {name!r}")
    return grid


def plan(
    fab: Fabric, robot: str, goal: tuple[float, float, float] | None, *, planner: str = "hybrid_astar", map_name: str = "map", timeout: float = 10.0,
    peer: str | None = None,
) -> Path:
    """A path from ``robot``'s pose to ``goal`` (None: the goal object's pose) from a compute peer."""
    m = _module("compute_peer.navigation.messages")
    req = m.PlanRequest(robot, goal=np.asarray(goal if goal is not None else (), dtype=float), planner=planner, map=map_name)
    reply = fab.call(_service_key(fab, "plan", robot, peer), req, timeout=timeout)
    path = reply if isinstance(reply, Path) else _get(reply, "path")
    if not isinstance(path, Path):
        raise ServiceError(f"plan reply without a path: {type(reply).__name__}")
    return path
