"""The recent poses of each robot the navigation service follows (pure: no session, no clock).

A scan is folded in at the pose nearest to it in sim time, and a plan starts from the latest pose, so each
robot keeps its last :data:`POSE_HISTORY` poses. Thread-safe: poses arrive on Zenoh's callback threads while
plans read them on query threads.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import replace

import numpy as np

from fabric.interfaces import Header, Pose

__all__ = ["MAX_ROBOTS", "POSE_HISTORY", "PoseHistory"]

POSE_HISTORY = 64
MAX_ROBOTS = 64
"""Robots whose poses are kept when no world description says which exist (a flood of made-up ids stops here)."""


class PoseHistory:
    """The last ``depth`` poses of each robot, newest last."""

    def __init__(self, depth: int = POSE_HISTORY) -> None:
        self._depth = depth
        self._poses: dict[str, deque[Pose]] = {}
        self._lock = threading.Lock()

    def __contains__(self, robot: object) -> bool:
        with self._lock:
            return robot in self._poses

    def __len__(self) -> int:
        with self._lock:
            return len(self._poses)

    def robots(self) -> set[str]:
        """The robots with at least one pose."""
        with self._lock:
            return set(self._poses)

    def add(self, robot: str, pose: Pose) -> bool:
        """Keep ``pose`` as the newest of ``robot``; True when it is the robot's first."""
        with self._lock:
            hist = self._poses.get(robot)
            first = hist is None
            if hist is None:
                hist = self._poses[robot] = deque(maxlen=self._depth)
            hist.append(pose)
            return first

    def at(self, robot: str, stamp: float = 0.0) -> Pose | None:
        """The pose at sim time ``stamp``: between two poses kept, the two interpolated (the header the nearest's,
        stamped ``stamp``); before or after them, the nearest; the latest when ``stamp`` <= 0; None before any.
        A scan falls between two poses (the sim's stream loops tick apart, and the robot turns 3.6 rad/s at speed
        3): the nearest pose alone put the warehouse's far shelves cells off in the map."""
        with self._lock:
            hist = self._poses.get(robot)
            if not hist:
                return None
            if stamp <= 0.0:
                return hist[-1]
            nearest = min(hist, key=lambda p: abs(p.header.stamp - stamp))
            before = max((p for p in hist if p.header.stamp <= stamp), key=lambda p: p.header.stamp, default=None)
            after = min((p for p in hist if p.header.stamp >= stamp), key=lambda p: p.header.stamp, default=None)
        if before is None or after is None or after.header.stamp <= before.header.stamp:
            return nearest
        return _between(before, after, (stamp - before.header.stamp) / (after.header.stamp - before.header.stamp),
                        replace(nearest.header, stamp=stamp))


def _between(a: Pose, b: Pose, f: float, header: Header) -> Pose:
    """``a`` and ``b`` mixed ``f`` of the way to ``b``: positions and speeds linearly, orientations along the shorter
    arc (normalised linear mix: the poses are a sim step or two apart)."""
    qb = b.quaternion if float(np.dot(a.quaternion, b.quaternion)) >= 0.0 else -b.quaternion
    q = (1.0 - f) * a.quaternion + f * qb
    return replace(a, position=(1.0 - f) * a.position + f * b.position, quaternion=q / np.linalg.norm(q),
                   linear=(1.0 - f) * a.linear + f * b.linear, angular=(1.0 - f) * a.angular + f * b.angular, header=header)
