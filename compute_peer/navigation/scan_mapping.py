"""Mapping mode: fold the robots' scans into one occupancy grid as they arrive (no session here).

Each scan is taken at the robot pose nearest to it in sim time, from where the robot's LIDAR sits on it, and
marks the disk the robot stands on free. Robots are moving obstacles, not the world: the cells under every robot
followed, where it stood when the scan was taken, are never marked occupied by it and are cleared
(:mod:`.robot_cells`); a robot of another sim counts along the last moments its mirror may lag it. A scan that cannot be placed (mapping off, no pose yet, mounting still
being looked up, malformed) is dropped and counted by reason, never raised: scans come from the wire. A rejected
scan is logged at most a few times per interval (with the count suppressed since), its reason clipped: a flood
of malformed scans must not fill the compute peer's log.
"""

from __future__ import annotations

import logging
import math
import threading
import time
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
        for name in ("scans", "scans_ignored", "scans_without_pose", "scans_out_of_step", "scans_waiting_for_sensor",
                     "scans_rejected"):
            counters.setdefault(name, 0)
        self._lock = threading.Lock()
        self._clock = clock
        self._reports = RateLimiter(REPORT_INTERVAL, burst=REPORT_BURST, max_keys=1)

    @property
    def scans(self) -> int:
        """Scans folded in since the start or the last reset."""
        with self._lock:
            return self.mapper.scans

    def integrate(self, robot: str, scan: Scan) -> bool:
        """Fold ``scan`` of ``robot`` in; False (and counted by reason) when it was dropped."""
        with self._lock:
            if not self.on:
                self.counters["scans_ignored"] += 1  # arrived while mapping was off
                return False
            pose = self.poses.known_at(robot, scan.header.stamp)
            if pose is None:
                # no pose at all, or none near enough its stamp: folded in at a moving robot's nearest pose, it smears the map
                self.counters["scans_without_pose" if robot not in self.poses else "scans_out_of_step"] += 1
                return False
            offset = self._sensor_offset(robot)
            if offset is None:
                self.counters["scans_waiting_for_sensor"] += 1  # the sensor's mounting is being looked up
                return False
            try:
                self.mapper.integrate_scan(scan, pose, sensor_offset=offset, footprint=self._radius(robot),
                                           robots=self.footprints(robot, scan.header, pose, reach=scan.range_max))
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
