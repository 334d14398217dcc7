"""Calls to the services other peers serve: the sim's world description, the compute peer's IK, map and plan.

The requests and replies are the typed messages of :mod:`fabric.interfaces` (``WorldInfo``,
``IKRequest``/``IKReply``, ``MapRequest``/``MapReply``, ``PlanRequest``/``PlanReply``); this module is
the one place that builds the requests and reads the replies, so the API above it deals only in numpy
arrays and fabric messages.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from fabric import keys, worldview
from fabric.interfaces import (
    IKReply,
    IKRequest,
    MapReply,
    MapRequest,
    OccupancyGrid,
    Path,
    PlanReply,
    PlanRequest,
    ServiceError,
    WorldInfo,
)
from fabric.session import Fabric

__all__ = ["RobotEntry", "robot_entries", "world_info", "ik", "map_request", "build_map", "plan", "plan_reply"]


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
    sim: str = ""  # the sim peer that is its authority


def robot_entries(info: WorldInfo) -> list[RobotEntry]:
    """Robots of a world description."""
    return [
        RobotEntry(
            r.id,
            r.type,
            r.kind,
            tuple(r.joint_names),
            tuple(float(v) for v in r.lower),
            tuple(float(v) for v in r.upper),
            tuple(float(v) for v in r.max_speed),
            r.sim,
        )
        for r in info.robots
    ]


def world_info(fab: Fabric, *, timeout: float = 5.0) -> WorldInfo:
    """The world's description (``rf/{world}/srv/world``): the union of every live sim's part, each robot with
    the sim that is its authority (``RobotInfo.sim``; :func:`fabric.worldview.describe`)."""
    return worldview.describe(fab, timeout=timeout)


def _service_key(fab: Fabric, service: str, subject: str, peer: str | None, user: str | None = None) -> str:
    """``srv/{service}/{subject}``: the nearest compute peer; with ``peer``, that compute peer only; with
    ``user``, asked in that user's name (``.../by/{user}``, what a class's router lets a student ask)."""
    if user is not None:
        return keys.srv_asked(fab.world, service, subject, user, peer)
    return keys.srv(fab.world, service, subject) if peer is None else keys.srv(fab.world, service, subject, peer)


def ik(
    fab: Fabric,
    robot: str,
    xyz: Sequence[float],
    quaternion: Sequence[float] | None,
    seed: Any,
    *,
    timeout: float = 5.0,
    peer: str | None = None,
) -> np.ndarray:
    """Joint angles for a flange position (world frame) from a compute peer (``peer``: a chosen one)."""
    req = IKRequest.make(xyz, quaternion, seed)
    reply = fab.rpc.call(_service_key(fab, "ik", robot, peer), req, timeout=timeout, expected=IKReply)
    return np.asarray(reply.q, dtype=float)


def map_request(
    fab: Fabric,
    action: str,
    *,
    name: str = "map",
    threshold: float = 0.65,
    timeout: float = 10.0,
    peer: str | None = None,
    user: str | None = None,
) -> MapReply:
    """One request to the mapping service on ``rf/{world}/srv/map/{name}`` (``.../by/{user}`` in ``user``'s
    name: set, reset, stop, save and load are then refused, docs/security.md); returns its MapReply."""
    req = MapRequest(action, name=name, threshold=threshold)
    return fab.rpc.call(_service_key(fab, "map", name, peer, user), req, timeout=timeout, expected=MapReply)


def build_map(
    fab: Fabric,
    *,
    name: str = "map",
    threshold: float = 0.65,
    timeout: float = 10.0,
    peer: str | None = None,
    user: str | None = None,
) -> OccupancyGrid:
    """Threshold the scans a compute peer accumulated into map ``name`` (also published on ``map/{name}``); asked
    in ``user``'s name it is her own map, ``{user}.{name}`` (:func:`fabric.keys.user_map`)."""
    reply = map_request(fab, "build", name=name, threshold=threshold, timeout=timeout, peer=peer, user=user)
    grid = reply.grid
    if grid.cells.size == 0:
        raise ServiceError(f"the map service built no grid for {name!r}")
    return grid


def plan(
    fab: Fabric,
    robot: str,
    goal: tuple[float, float, float] | None,
    *,
    planner: str = "hybrid_astar",
    map_name: str = "map",
    timeout: float = 10.0,
    peer: str | None = None,
    user: str | None = None,
) -> Path:
    """A path from ``robot``'s pose to ``goal`` (None: the goal object's pose) from a compute peer; asked in
    ``user``'s name, it is published on the robot's ``path`` key only if she owns the robot (else in the reply only)."""
    return plan_reply(fab, robot, goal, planner=planner, map_name=map_name, timeout=timeout, peer=peer, user=user).path


def plan_reply(
    fab: Fabric,
    robot: str,
    goal: tuple[float, float, float] | None,
    *,
    planner: str = "hybrid_astar",
    map_name: str = "map",
    timeout: float = 10.0,
    peer: str | None = None,
    user: str | None = None,
    direction: str = "default",
) -> PlanReply:
    """:func:`plan`'s whole reply: the path, and ``note``, what the planner did to a start or goal near an
    obstacle (an escape move first, a goal moved; docs/navigation.md). ``direction``: "default", "forward", "both"."""
    req = PlanRequest(
        robot,
        goal=np.asarray(goal if goal is not None else (), dtype=float),
        planner=planner,
        map=map_name,
        direction=direction,
    )
    return fab.rpc.call(_service_key(fab, "plan", robot, peer, user), req, timeout=timeout, expected=PlanReply)
