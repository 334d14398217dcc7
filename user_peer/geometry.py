"""Pure geometry for drawing a world: where a pose, a scan, a map pixel or an arm link lies.

Apart from :mod:`user_peer.rerun_log`, so that the logger only maps messages to Rerun
calls, and these helpers can be read and tested without Rerun: numpy and the fabric's messages only.
Quaternions come in two orders here on purpose: fabric messages carry (w, x, y, z) (MuJoCo's order),
Rerun and :class:`user_peer.arm_geometry.Placement` use (x, y, z, w).
"""

from __future__ import annotations

import math

import numpy as np

from fabric.interfaces import OccupancyGrid, Pose, Scan, yaw_from_quaternion
from ownership.extrapolate import age_s, extrapolate
from user_peer.arm_geometry import Placement

__all__ = [
    "EXTRAPOLATION_CAP_S",
    "compose",
    "grid_rgb",
    "quat_mul_xyzw",
    "quat_xyzw",
    "rotation_xyzw",
    "scan_world_points",
    "shown_position",
    "world_to_map_pixels",
    "yaw_of",
]

EXTRAPOLATION_CAP_S = 0.2  # s: never move a stale pose further than its velocity times this (paper Eq. 8)


yaw_of = yaw_from_quaternion
"""Heading (rad) of a (w, x, y, z) quaternion about the world z axis: the views' name for
:func:`fabric.interfaces.yaw_from_quaternion` (one definition)."""


def shown_position(pose: Pose, received_ns: int, now_ns: int) -> tuple[np.ndarray, float | None]:
    """Where to draw a remote pose at ``now_ns``, and its age in s (None when either time is unknown).

    The paper's Eq. 8: the pose moved on by its velocity times its age, the age capped so that a stale
    message never flings a robot across the room. ``received_ns`` (when it arrived) and ``now_ns`` are
    both read from this machine's clock: the header's ``wall_ns`` is the sender's clock, which may be
    seconds off ours on another machine, and is never compared with ours.
    """
    if received_ns <= 0 or now_ns <= 0:
        return np.asarray(pose.position, dtype=float), None
    age = age_s(received_ns, now_ns, cap_s=EXTRAPOLATION_CAP_S)
    return extrapolate(pose.position, pose.linear, age, cap_s=EXTRAPOLATION_CAP_S), age


def scan_world_points(
    scan: Scan, pose: Pose | None, lidar_offset: tuple[float, float, float] = (0.0, 0.0, 0.3)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origin (3,), hit points (n, 3), hit mask (n,)) of a planar scan in the world frame.

    Rays that read ``range_max`` hit nothing; they are returned but masked out of the hits.
    Without a pose the scan is drawn at the world origin.
    """
    px, py, yaw = 0.0, 0.0, 0.0
    if pose is not None:
        px, py = float(pose.position[0]), float(pose.position[1])
        yaw = yaw_of(pose.quaternion)
    c, s = math.cos(yaw), math.sin(yaw)
    ox = px + c * lidar_offset[0] - s * lidar_offset[1]
    oy = py + s * lidar_offset[0] + c * lidar_offset[1]
    oz = lidar_offset[2]
    ranges = scan.ranges
    angles = scan.angles + yaw
    pts = np.stack([ox + ranges * np.cos(angles), oy + ranges * np.sin(angles), np.full_like(ranges, oz)], axis=1)
    hit = scan.ranges_mm < int(round(scan.range_max * 1000.0))
    return np.array([ox, oy, oz]), pts, hit


def grid_rgb(grid: OccupancyGrid) -> np.ndarray:
    """An (h, w, 3) uint8 image of a grid, row 0 at the top = the map's highest y (so north is up).

    Free cells are white, occupied black, shades between, unknown mid grey.
    """
    cells = np.asarray(grid.cells)
    unknown = cells == OccupancyGrid.UNKNOWN
    shade = (255 - (np.clip(cells, 0, 100).astype(np.float32) * 2.55)).astype(np.uint8)
    shade[unknown] = 128
    img = np.repeat(shade[:, :, None], 3, axis=2)
    img[unknown] = (150, 160, 180)
    return np.ascontiguousarray(img[::-1])


def world_to_map_pixels(grid: OccupancyGrid, xy: np.ndarray) -> np.ndarray:
    """World (x, y) points to pixel coordinates of :func:`grid_rgb`'s image (u right, v down)."""
    xy = np.atleast_2d(np.asarray(xy, dtype=float))
    ox, oy, oth = (float(v) for v in grid.origin)
    dx, dy = xy[:, 0] - ox, xy[:, 1] - oy
    c, s = math.cos(-oth), math.sin(-oth)
    lx, ly = c * dx - s * dy, s * dx + c * dy
    h = grid.cells.shape[0]
    return np.stack([lx / grid.resolution, h - ly / grid.resolution], axis=1)


def quat_xyzw(quat_wxyz: np.ndarray) -> list[float]:
    """A (w, x, y, z) quaternion as the [x, y, z, w] list Rerun and Pinocchio placements use."""
    w, x, y, z = (float(v) for v in quat_wxyz)
    return [x, y, z, w]


def compose(base: Placement | None, p: Placement) -> tuple[np.ndarray, list[float]]:
    """base * p, as (translation, quaternion xyzw)."""
    if base is None:
        return p.translation, list(p.quat_xyzw)
    rb = rotation_xyzw(base.quat_xyzw)
    t = base.translation + rb @ p.translation
    q = quat_mul_xyzw(base.quat_xyzw, p.quat_xyzw)
    return t, list(q)


def rotation_xyzw(q: np.ndarray) -> np.ndarray:
    """The 3x3 rotation matrix of an (x, y, z, w) unit quaternion."""
    x, y, z, w = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_mul_xyzw(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The Hamilton product a * b of two (x, y, z, w) quaternions."""
    ax, ay, az, aw = (float(v) for v in a)
    bx, by, bz, bw = (float(v) for v in b)
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )
