"""Mapping mode: fold the robots' scans into one occupancy grid as they arrive (no session here).

Each scan is taken at the robot pose nearest to it in sim time, from where the robot's LIDAR sits on it, and
marks the disk the robot stands on free. Robots are moving obstacles, not the world: the cells under every robot
followed, where it stood when the scan was taken, are never marked occupied by it and are cleared
(:mod:`.robot_cells`); a robot of another sim counts along the last moments its mirror may lag it. A scan that cannot be placed (mapping off, no pose yet, mounting still
being looked up, malformed) is dropped and counted by reason, never raised: scans come from the wire. A scan
stamped after its moving robot's newest pose is held until a pose at or after its stamp arrives (as tf2's message
filter does), at most :data:`HOLD_SECONDS`: the sim publishes poses and scans from loops of their own, so a scan
often arrives a pose period before the pose it lies behind. A rejected
scan is logged at most a few times per interval (with the count suppressed since), its reason clipped: a flood
of malformed scans must not fill the compute peer's log.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from typing import Callable

from fabric.interfaces import Header, OccupancyGrid, Pose, Scan
from fabric.limits import RateLimiter, clip, quote

from .errors import NavigationError
from .mapping import MapperConfig, OccupancyMapper
from .poses import PoseHistory
from .robot_cells import Footprint

log = logging.getLogger("robofabric.navigation")

REPORT_INTERVAL = 5.0  # seconds: rejected scans are logged at most REPORT_BURST times per interval
REPORT_BURST = 3
HOLD_SECONDS = 0.5  # wall seconds a scan ahead of its robot's poses waits for the pose after it, then dropped
HOLD_DEPTH = 16  # scans held per robot (0.8 s of a 20 Hz LIDAR); the oldest is dropped past it
BEYOND = 1.0  # metres past a scan's range (plus the robot's radius) within which a robot still counts for it

__all__ = ["ScanMapping"]


class ScanMapping:
    """An :class:`OccupancyMapper` fed with scans while ``on``; counts into ``counters``.

    ``sensor_offset(robot)``: the LIDAR mounting, or None while it is unknown yet. ``radius(robot)``: the robot's
    footprint radius.
    """

    def __init__(
        self,
        poses: PoseHistory,
        *,
        sensor_offset: Callable[[str], tuple[float, float, float] | None],
        radius: Callable[[str], float],
        counters: dict[str, int],
        config: MapperConfig | None = None,
        on: bool = True,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.poses = poses
        self.mapper = OccupancyMapper(config)
        self.on = bool(on)
        self._sensor_offset = sensor_offset
        self._radius = radius
        self.counters = counters
        for name in (
            "scans",
            "scans_ignored",
            "scans_without_pose",
            "scans_held",
            "scans_out_of_step",
            "scans_waiting_for_sensor",
            "scans_rejected",
        ):
            counters.setdefault(name, 0)
        self._lock = threading.Lock()
        self._clock = clock
        self._reports = RateLimiter(REPORT_INTERVAL, burst=REPORT_BURST, max_keys=1)
        self._held: dict[str, deque[tuple[float, Scan]]] = {}  # robot -> (wall time held, scan), oldest first

    @property
    def scans(self) -> int:
        """Scans folded in since the start or the last reset."""
        with self._lock:
            return self.mapper.scans

    def integrate(self, robot: str, scan: Scan) -> bool:
        """Fold ``scan`` of ``robot`` in; False when it was dropped (counted by reason) or held for a later pose
        (``scans_held``: :meth:`pose_added` folds it in)."""
        with self._lock:
            if not self.on:
                self.counters["scans_ignored"] += 1  # arrived while mapping was off
                return False
            pose = self.poses.known_at(robot, scan.header.stamp)
            if pose is None:
                latest = self.poses.at(robot)
                if latest is not None and scan.header.stamp > latest.header.stamp:
                    self._hold(robot, scan)  # ahead of its robot's poses: the pose after it is on its way
                    return False
                # no pose at all, or none near enough its stamp: folded in at a moving robot's nearest pose, it smears the map
                self.counters["scans_without_pose" if latest is None else "scans_out_of_step"] += 1
                return False
            return self._fold(robot, scan, pose)

    def pose_added(self, robot: str) -> int:
        """Fold in the scans held for ``robot`` that its newest pose now reaches; drop those held past
        :data:`HOLD_SECONDS` (``scans_out_of_step``). Returns how many were folded in."""
        with self._lock:
            held = self._held.get(robot)
            if not held:
                return 0
            latest = self.poses.at(robot)
            now = self._clock()
            folded = 0
            while held:
                since, scan = held[0]
                pose = (
                    None
                    if latest is None or scan.header.stamp > latest.header.stamp
                    else self.poses.known_at(robot, scan.header.stamp)
                )
                if pose is None and now - since <= HOLD_SECONDS:
                    break  # still ahead of the poses (they come in order: so are the scans after it)
                held.popleft()
                if not self.on:
                    self.counters["scans_ignored"] += 1
                elif pose is None:
                    self.counters["scans_out_of_step"] += 1
                elif self._fold(robot, scan, pose):
                    folded += 1
            if not held:
                del self._held[robot]
            return folded

    def _hold(self, robot: str, scan: Scan) -> None:
        held = self._held.setdefault(robot, deque())
        if len(held) >= HOLD_DEPTH:
            held.popleft()
            self.counters["scans_out_of_step"] += 1  # its pose never came in time
        held.append((self._clock(), scan))
        self.counters["scans_held"] += 1

    def _fold(self, robot: str, scan: Scan, pose: Pose) -> bool:
        offset = self._sensor_offset(robot)
        if offset is None:
            self.counters["scans_waiting_for_sensor"] += 1  # the sensor's mounting is being looked up
            return False
        try:
            self.mapper.integrate_scan(
                scan,
                pose,
                sensor_offset=offset,
                footprint=self._radius(robot),
                robots=self.footprints(robot, scan.header, pose, reach=scan.range_max),
            )
        except NavigationError as exc:
            self.counters["scans_rejected"] += 1
            verdict = self._reports.check("scan_rejected", self._clock())  # one fixed key: robot ids come from the wire
            if verdict:
                more = f" ({verdict.suppressed} more rejected since the last report)" if verdict.suppressed else ""
                log.warning("scan from %s rejected: %s%s", quote(robot, 64), clip(str(exc)), more)
            return False
        self.counters["scans"] += 1
        return True

    def footprints(self, scanner: str, header: Header, pose: Pose, *, reach: float = math.inf) -> list[Footprint]:
        """Where the other robots followed stood when ``scanner``'s scan with ``header`` was taken (``pose``: the
        scanner's); robots farther than ``reach`` (the scan's range) + :data:`BEYOND` from it are left out: the scan
        cannot have seen them, and their own scans clear where they stand. The scanner is not among them: no
        LIDAR sees its own robot, and its disk (radius only, no margin: a wall beside it stays) is marked free
        with each of its scans."""
        x, y = float(pose.position[0]), float(pose.position[1])
        out = []
        for robot in self.poses.robots() - {scanner}:
            radius = self._radius(robot)
            for p in self.poses.during(robot, header):
                px, py = float(p.position[0]), float(p.position[1])
                if math.hypot(px - x, py - y) <= reach + radius + BEYOND:
                    out.append(Footprint(px, py, radius))
        return out

    def grid(self, *, threshold: float | None = None, header: Header | None = None) -> OccupancyGrid | None:
        """The map so far (binary with ``threshold``, else probabilities in percent); None before any scan."""
        with self._lock:
            if self.mapper.scans == 0:
                return None
            return self.mapper.grid(threshold=threshold, header=header)

    def reset(self) -> None:
        """Forget every scan (mapping stays on or off as it was)."""
        with self._lock:
            self.mapper.reset()
            self._held.clear()
