"""The recent poses of each robot the navigation service follows (pure: no session, no clock).

A scan is folded in at the pose nearest to it in sim time, knowing where every other robot stood then
(:meth:`PoseHistory.during`: robots are not walls, :mod:`.robot_cells`), and a plan starts from the latest pose,
so each robot keeps its last :data:`POSE_HISTORY` poses. Thread-safe: poses arrive on Zenoh's callback threads while
plans read them on query threads.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import replace
from typing import Callable

import numpy as np

from fabric.interfaces import Header, Pose

__all__ = ["FOLD_ANGLE", "FOLD_DISTANCE", "MAX_ROBOTS", "MIRROR_LAG", "POSE_HISTORY", "SPREAD", "STALE", "PoseHistory"]

POSE_HISTORY = 64
MAX_ROBOTS = 64
"""Robots whose poses are kept when no world description says which exist (a flood of made-up ids stops here)."""
MIRROR_LAG = 0.3
"""Seconds another sim's mirror of a robot may lag it (a pose period plus transport; p99 0.11-0.5 s on a loaded
2-core box, docs/benchmarks.md "shards"): a scan of that sim may have seen the robot anywhere along them."""
FOLD_ANGLE = 0.02
"""Radians a robot may turn between the nearest pose kept and a scan's stamp beyond them for the scan to be folded in."""
FOLD_DISTANCE = 0.02
"""Metres a robot may move between the nearest pose kept and a scan's stamp beyond them (half a 5 cm cell)."""
STALE = 2.0
"""Seconds from a scan beyond which a robot's nearest pose says nothing about where it stood (it left)."""


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
            hist = list(self._poses.get(robot, ()))
        if not hist:
            return None
        if stamp <= 0.0:
            return hist[-1]
        return _interpolated(hist, stamp, _sim_time)

    def known_at(
        self, robot: str, stamp: float, *, angle: float = FOLD_ANGLE, distance: float = FOLD_DISTANCE
    ) -> Pose | None:
        """The pose at sim time ``stamp`` (:meth:`at`), or None when ``stamp`` lies beyond the poses kept by more
        than the robot's motion there allows: its speed at the nearest end times the time beyond it would turn it
        more than ``angle`` rad or move it more than ``distance`` m. A scan folded in at such a pose smears the map:
        a spinning base's poses arriving 0.1 s behind its scans, as on a loaded box, turned each scan by 7 degrees,
        walls 3 m off by 0.36 m (a class of 4 mapped shelves' faces up to 1 m out). ROS's tf refuses to extrapolate
        for the same reason. A base standing still is known at any time near its poses."""
        with self._lock:
            hist = list(self._poses.get(robot, ()))
        if not hist:
            return None
        if stamp > 0.0:
            end = hist[0] if stamp < hist[0].header.stamp else hist[-1] if stamp > hist[-1].header.stamp else None
            if end is not None:
                beyond = abs(stamp - end.header.stamp)
                if abs(float(end.angular[2])) * beyond > angle or float(np.hypot(*end.linear[:2])) * beyond > distance:
                    return None
        return self.at(robot, stamp)

    def during(self, robot: str, header: Header, *, lag: float = MIRROR_LAG, stale: float = STALE) -> list[Pose]:
        """Where ``robot`` stood when the message with ``header`` (a scan) was taken: [] when no pose of it is
        within ``stale`` seconds of that moment (a robot that left, or none yet).

        A robot of the same sim as the scan (same ``source``): its pose interpolated to the scan's sim time
        (the latest when stamps are 0). A robot of another sim (another clock): that sim's scan saw its
        mirror, which lags it by a stream period plus transport, so the poses of the last ``lag`` seconds
        before the scan's wall time (one a cell apart is enough: :data:`SPREAD`), and the one interpolated to it.
        Called for every robot with every scan: it walks back from the newest pose (poses arrive in time order,
        and a scan is recent), not over the whole history."""
        with self._lock:
            hist = list(self._poses.get(robot, ()))
        if not hist:
            return []
        if hist[-1].header.source == header.source:
            if header.stamp <= 0.0:
                return [hist[-1]]
            at, _ = _walk_back(hist, header.stamp, _sim_time, stale, 0.0)
            return at
        at, window = _walk_back(hist, header.wall_ns * 1e-9, _wall_time, stale, lag)
        return window + at if at else []


SPREAD = 0.05
"""Metres between two poses of a mirrored robot's lag that both count: closer ones add no cell to its footprint."""


def _walk_back(
    hist: list[Pose], t: float, when: Callable[[Pose], float], stale: float, lag: float
) -> tuple[list[Pose], list[Pose]]:
    """([the pose at ``t``] or [] when the nearest is more than ``stale`` away, the poses of [t - lag, t) at least
    :data:`SPREAD` apart), walking back from the newest of ``hist``."""
    i = len(hist) - 1
    while i >= 0 and when(hist[i]) > t:
        i -= 1
    if i == len(hist) - 1:  # after the newest
        nearest, at = hist[-1], hist[-1]
    elif i < 0:  # before the oldest kept
        nearest, at = hist[0], hist[0]
    else:
        a, b = hist[i], hist[i + 1]
        nearest = a if t - when(a) <= when(b) - t else b
        header = replace(nearest.header, stamp=t) if when is _sim_time else nearest.header
        at = _between(a, b, (t - when(a)) / (when(b) - when(a)), header) if when(b) > when(a) else nearest
    if abs(when(nearest) - t) > stale:
        return [], []
    window: list[Pose] = []
    last = at.position
    while i >= 0 and when(hist[i]) >= t - lag:
        p = hist[i]
        if float(np.hypot(p.position[0] - last[0], p.position[1] - last[1])) >= SPREAD:
            window.append(p)
            last = p.position
        i -= 1
    return [at], window


def _sim_time(p: Pose) -> float:
    return p.header.stamp


def _wall_time(p: Pose) -> float:
    return p.header.wall_ns * 1e-9


def _interpolated(hist: list[Pose], t: float, when: Callable[[Pose], float]) -> Pose:
    """The pose at time ``t`` by the clock ``when``: the two kept around it interpolated, else the nearest."""
    nearest = min(hist, key=lambda p: abs(when(p) - t))
    before = max((p for p in hist if when(p) <= t), key=when, default=None)
    after = min((p for p in hist if when(p) >= t), key=when, default=None)
    if before is None or after is None or when(after) <= when(before):
        return nearest
    header = replace(nearest.header, stamp=t) if when is _sim_time else nearest.header
    return _between(before, after, (t - when(before)) / (when(after) - when(before)), header)


def _between(a: Pose, b: Pose, f: float, header: Header) -> Pose:
    """``a`` and ``b`` mixed ``f`` of the way to ``b``: positions and speeds linearly, orientations along the shorter
    arc (normalised linear mix: the poses are a sim step or two apart)."""
    qb = b.quaternion if float(np.dot(a.quaternion, b.quaternion)) >= 0.0 else -b.quaternion
    q = (1.0 - f) * a.quaternion + f * qb
    return replace(
        a,
        position=(1.0 - f) * a.position + f * b.position,
        quaternion=q / np.linalg.norm(q),
        linear=(1.0 - f) * a.linear + f * b.linear,
        angular=(1.0 - f) * a.angular + f * b.angular,
        header=header,
    )
