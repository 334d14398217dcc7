"""What the console's 3D view draws, as numbers: an arm's joint frames in the world, a link as a cylinder's pose,
the scene's static boxes with their orientation.

Pure functions of a robot's description, its joints and its spawn pose (no session, no browser), so they are
tested alone; :mod:`.view3d` puts them on the page with NiceGUI's ``ui.scene`` (three.js, z up, metres).
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from user_peer.console.state import arm_chain

__all__ = ["Box3", "arm_points", "segment_pose", "quat_matrix", "scene_boxes3d"]

log = logging.getLogger("robofabric.console")


def arm_points(robot_type: str, q: Sequence[float] | None, spawn: Sequence[float]) -> np.ndarray:
    """An arm's joint frames' origins in the world (N x 3), its base first: the forward kinematics of its URDF at
    joints ``q``, placed at its spawn pose (x, y, z, yaw). Empty (0 x 3) when the chain is unknown or ``q`` does
    not fit it: the view then draws the base alone."""
    chain = arm_chain(robot_type)
    if chain is None or q is None or len(q) != chain.nq:
        return np.zeros((0, 3))
    sx, sy, sz, yaw = (float(v) for v in spawn)
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    pts = np.vstack([np.zeros((1, 3)), np.asarray(chain.origins(q), dtype=float)])
    return pts @ R.T + np.array([sx, sy, sz])


def segment_pose(a: Sequence[float], b: Sequence[float]) -> tuple[np.ndarray, np.ndarray, float]:
    """The pose of a link drawn from ``a`` to ``b`` as a three.js cylinder of height 1 (its axis is its local y):
    the midpoint, the rotation taking y onto ``b - a``, and the length to scale y by."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d = b - a
    n = float(np.linalg.norm(d))
    mid = (a + b) / 2.0
    if n < 1e-9:
        return mid, np.eye(3), 0.0
    y = d / n
    helper = np.array([0.0, 0.0, 1.0]) if abs(y[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(y, helper)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    return mid, np.stack([x, y, z], axis=1), n


def quat_matrix(q_xyzw: Sequence[float]) -> np.ndarray:
    """A unit quaternion (x, y, z, w) as a 3 x 3 rotation matrix."""
    x, y, z, w = (float(v) for v in q_xyzw)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@dataclass(frozen=True, slots=True)
class Box3:
    """A static part of the scene (a wall, a shelf) as the 3D view draws it."""

    name: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]  # full sizes along its own x, y, z
    R: tuple[tuple[float, float, float], ...]  # its orientation (3 x 3, rows)
    color: str


@functools.lru_cache(maxsize=8)
def scene_boxes3d(scene: str) -> tuple[Box3, ...]:
    """The scene's static boxes from its MJCF when this install has it (the sim extra), the floor left out (the
    view has its own ground and grid); none otherwise. Read once per scene."""
    try:
        import robots
        from user_peer.scene_geometry import static_boxes

        out = []
        for b in static_boxes(robots.scene(scene).mjcf_path):
            if b.half_size[2] < 0.01:
                continue
            r, g, bl, _ = b.rgba
            out.append(
                Box3(
                    b.name,
                    tuple(float(v) for v in b.center),
                    tuple(float(2 * v) for v in b.half_size),
                    tuple(tuple(float(v) for v in row) for row in quat_matrix(b.quat_xyzw)),
                    f"#{r:02x}{g:02x}{bl:02x}",
                )
            )
        return tuple(out)
    except Exception as exc:  # no mujoco (a student's install), or a scene this install does not have
        log.info("no static geometry for scene %r: %s", scene, exc)
        return ()
