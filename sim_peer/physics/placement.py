"""Where robots go: ``TYPE:ID@X,Y`` specs, and a free spot for robots given without a pose.

Auto-placement walks a square spiral of 0.8 m cells from the first mobile robot's spot (or the origin) and
takes the first cell whose circle of the robot's radius is clear of placed robots and, by ray casts at
three heights in the bare scene, of the scene's geometry.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import mujoco
import numpy as np

from fabric.keys import validate_id
from robots import RobotDescription, SceneRobot
from robots.kinds import robot_kind
from sim_peer.physics.errors import WorldError
from sim_peer.sensors import SENSED_GROUPS

CELL = 0.8  # m between candidate spots
PROBE_HEIGHTS = (0.05, 0.3, 0.8)  # m: floor clutter, tables, shelves
DEFAULT_RADIUS = 0.3  # m, for robots whose description gives no base radius


def parse_robot_spec(spec: str) -> SceneRobot:
    """``TYPE:ID`` or ``TYPE:ID@X,Y[,YAW[,Z]]`` (metres, degrees) -> SceneRobot (pose NaN = place automatically)."""
    head, _, where = spec.partition("@")
    rtype, sep, rid = head.partition(":")
    if not sep or not rtype or not rid:
        raise WorldError(f"robot {spec!r}: expected TYPE:ID or TYPE:ID@X,Y[,YAW_DEG[,Z]]")
    try:
        validate_id(rid, what="robot id")
    except ValueError as exc:
        raise WorldError(f"robot {spec!r}: {exc}") from None
    if not where:
        return SceneRobot(rtype, rid, (math.nan, math.nan, 0.0, 0.0))
    try:
        vals = [float(v) for v in where.split(",")]
    except ValueError:
        raise WorldError(f"robot {spec!r}: pose must be numbers X,Y[,YAW_DEG[,Z]]") from None
    if not 2 <= len(vals) <= 4 or not all(math.isfinite(v) for v in vals):
        raise WorldError(f"robot {spec!r}: pose must be 2 to 4 finite numbers X,Y[,YAW_DEG[,Z]]")
    x, y = vals[0], vals[1]
    yaw = math.radians(vals[2]) if len(vals) > 2 else 0.0
    z = vals[3] if len(vals) > 3 else 0.0
    return SceneRobot(rtype, rid, (x, y, z, yaw))


def unplaced(r: SceneRobot) -> bool:
    return math.isnan(r.pose[0])


def place(
    scene_mjcf: Path, robots: Sequence[SceneRobot], descriptions: Mapping[str, RobotDescription]
) -> list[SceneRobot]:
    """``robots`` with a free spot for each one given without a pose (the others as they are)."""
    if not any(unplaced(r) for r in robots):
        return list(robots)
    probe = mujoco.MjModel.from_xml_path(str(scene_mjcf))
    pd = mujoco.MjData(probe)
    mujoco.mj_forward(probe, pd)

    def radius(r: SceneRobot) -> float:
        return descriptions[r.id].base_radius or DEFAULT_RADIUS

    taken = [(r.pose[0], r.pose[1], radius(r)) for r in robots if not unplaced(r)]
    mobile = [r for r in robots if not unplaced(r) and robot_kind(descriptions[r.id].kind).base]
    ox, oy = (mobile[0].pose[0], mobile[0].pose[1]) if mobile else (0.0, 0.0)
    dirs = np.array([[math.cos(a), math.sin(a), 0.0] for a in np.linspace(0, 2 * math.pi, 24, endpoint=False)]).reshape(
        -1
    )
    gid, dist = np.zeros(24, np.int32), np.zeros(24)
    cells = spiral(400)
    out = []
    for r in robots:
        if not unplaced(r):
            out.append(r)
            continue
        rad = radius(r)
        for i, j in cells:
            x, y = ox + CELL * i, oy + CELL * j
            if any(math.hypot(x - tx, y - ty) < rad + tr + 0.05 for tx, ty, tr in taken):
                continue
            free = True
            for h in PROBE_HEIGHTS:
                mujoco.mj_multiRay(
                    probe, pd, np.array([x, y, h]), dirs, SENSED_GROUPS, 1, -1, gid, dist, None, 24, rad + 0.1
                )
                if ((dist >= 0) & (dist < rad + 0.1)).any():  # cutoff is only a bounding-sphere filter
                    free = False
                    break
            if free:
                taken.append((x, y, rad))
                out.append(SceneRobot(r.type, r.id, (x, y, r.pose[2], r.pose[3])))
                break
        else:
            raise WorldError(f"no free spot found for robot {r.id}; give it a pose with TYPE:ID@X,Y")
    return out


def spiral(n: int) -> list[tuple[int, int]]:
    """Grid cells in a square spiral from (0, 0)."""
    cells = [(0, 0)]
    x = y = 0
    dx, dy = 1, 0
    leg = 1
    while len(cells) < n:
        for _ in range(2):
            for _ in range(leg):
                x, y = x + dx, y + dy
                cells.append((x, y))
            dx, dy = -dy, dx
        leg += 1
    return cells[:n]


__all__ = ["parse_robot_spec", "place", "spiral", "unplaced"]
