"""The recent poses of each robot the navigation service follows (pure: no session, no clock).

A scan is folded in at the pose nearest to it in sim time, and a plan starts from the latest pose, so each
robot keeps its last :data:`POSE_HISTORY` poses. Thread-safe: poses arrive on Zenoh's callback threads while
plans read them on query threads.
"""

from __future__ import annotations

import threading
from collections import deque

from fabric.interfaces import Pose

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
        """The pose nearest in sim time to ``stamp`` (the latest one when ``stamp`` <= 0); None before any."""
        with self._lock:
            hist = self._poses.get(robot)
            if not hist:
                return None
            if stamp <= 0.0:
                return hist[-1]
            return min(hist, key=lambda p: abs(p.header.stamp - stamp))
