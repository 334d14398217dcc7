"""Shared helpers of the navigation tests: a small known scene, drives through it, geometric checks."""

from __future__ import annotations

import math

import numpy as np

from compute_peer.navigation.scenes import Scene, room, scan_angles
from fabric.interfaces import Header, Pose, Scan, quaternion_from_yaw

RAYS = 240
FOV = 270.0
RANGE_MAX = 8.0


def small_room() -> Scene:
    """A 10 m x 10 m room with an inner wall (gap at the top) and a pillar."""
    boxes = room(10.0, 0.2) + [(4.0, 0.0, 4.3, 7.0), (6.5, 3.0, 7.5, 4.0)]
    return Scene(tuple(boxes), (0.0, 0.0, 10.0, 10.0))


def free_of(scene: Scene, x: float, y: float, clearance: float) -> bool:
    return all(box_distance(b, x, y) > clearance for b in scene.boxes)


def box_distance(b, x, y):
    """Euclidean distance from point(s) to an axis-aligned box (0 inside)."""
    dx = np.maximum(np.maximum(b[0] - x, 0.0), x - b[2])
    dy = np.maximum(np.maximum(b[1] - y, 0.0), y - b[3])
    return np.hypot(dx, dy)


def scene_clearance(scene: Scene, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.min([box_distance(b, x, y) for b in scene.boxes], axis=0)


def drive_poses(scene: Scene, step: float = 1.0, clearance: float = 0.4) -> list[tuple[float, float, float]]:
    """Poses on a lattice over the free space, each with a different heading (a user driving around)."""
    x0, y0, x1, y1 = scene.bounds
    out = []
    k = 0
    for y in np.arange(y0 + 0.7, y1 - 0.5, step):
        for x in np.arange(x0 + 0.7, x1 - 0.5, step):
            if free_of(scene, x, y, clearance):
                out.append((float(x), float(y), (k * 2.399) % (2 * math.pi) - math.pi))
                k += 1
    return out


def scan_at(scene: Scene, x: float, y: float, yaw: float, *, stamp: float = 0.0, seq: int = 0) -> Scan:
    amin, ainc = scan_angles(RAYS, FOV)
    rel = amin + ainc * np.arange(RAYS)
    ranges = scene.raycast(x, y, rel + yaw, RANGE_MAX)
    return Scan.from_ranges(
        ranges, angle_min=amin, angle_increment=ainc, range_max=RANGE_MAX, header=Header(stamp=stamp, seq=seq)
    )


def pose_at(x: float, y: float, yaw: float, *, stamp: float = 0.0, seq: int = 0) -> Pose:
    return Pose(np.array([x, y, 0.0]), quaternion_from_yaw(yaw), header=Header(stamp=stamp, seq=seq))
