"""What the navigation service learns about the world's mobile robots from the sim peers' ``srv/world``.

Where each robot's LIDAR sits on it, (x, y, yaw) in the robot frame, the robot's radius, and whether it may drive
backwards along a path (its plans' default direction). A scan folded in
from the wrong mounting blurs walls (the Reeman's LIDAR is 0.22 m ahead of its axle), so a new robot's scans wait
while its description is looked up; the lookup runs on a thread of its own, at most once a second, because it is
a query and scans arrive on Zenoh's callback threads. Once a sim has answered, the robots it described are the
only ones followed (plus those already followed), so made-up ids on the robot keys cost nothing.
"""

from __future__ import annotations

import logging
import math
import threading
from typing import TYPE_CHECKING, Callable, Iterable

from fabric.interfaces import ServiceError
from fabric.rate import Clock, MonotonicClock
from robots.kinds import facts

from ..world_lookup import BackgroundLookup, described_robots

if TYPE_CHECKING:
    from fabric.session import Fabric

log = logging.getLogger("robofabric.navigation")

__all__ = ["RobotDescriptions"]

UNANSWERED_S = 10.0
"""Seconds a new robot's scans wait for the sims to answer ``srv/world`` before its LIDAR is taken to sit on its
axle: a sim loaded enough to miss a lookup's 2 s answers a later one (4 students' class on 2 loaded cores missed
22), and a scan folded in from the wrong mounting blurs walls, and other robots out of their footprints."""

Offset = tuple[float, float, float]
NO_OFFSET: Offset = (0.0, 0.0, 0.0)


class RobotDescriptions:
    """Each mobile robot's LIDAR mounting and radius: given, or learnt from ``srv/world`` when ``discover``.

    ``sensor_offset`` (all robots) / ``sensor_offsets`` (per robot) are given mountings and are never overridden.
    ``followed``: the robots the service already follows (they stay followed whatever a sim says).
    ``clock``: for the lookup's rate limit.
    """

    def __init__(
        self,
        fabric: "Fabric",
        *,
        followed: Callable[[], Iterable[str]],
        sensor_offset: Offset | None = None,
        sensor_offsets: dict[str, Offset] | None = None,
        discover: bool = True,
        clock: Clock | None = None,
    ) -> None:
        self.fabric = fabric
        self.world = fabric.world
        self._followed = followed
        self.sensor_offset_all = sensor_offset
        self._offsets: dict[str, Offset] = dict(sensor_offsets or {})
        self._radii: dict[str, float] = {}
        self._reverse: dict[str, bool] = {}
        self._discover = bool(discover)
        self._clock = clock or MonotonicClock()
        self._first_seen: dict[str, float] = {}
        self._described: set[str] | None = None  # mobile robots of the world, once a sim described them
        self._not_mobile: set[str] = set()  # the world's other robots (an arm publishes its flange's pose)
        self._answered_at = -math.inf  # the clock time a lookup last got the sims' answer
        self._lookup = BackgroundLookup(
            self.discover,
            name="nav-discovery",
            clock=self._clock,
            on_error=lambda exc: log.debug("robot discovery failed: %s", exc),
        )
        self._lock = threading.RLock()
        self.on_described: Callable[[set[str]], None] | None = None
        """Called with the mobile robots to hear after each lookup the sims answered (outside the lock): the ones
        described, and the ones followed that no sim described as another kind."""

    def close(self) -> None:
        """No lookup starts after this (one under way ends on its own)."""
        self._lookup.close()

    # ------------------------------------------------------------------ reading

    def admits(self, robot: str) -> bool:
        """False for a robot the world's sims described without it (True before any sim answered)."""
        with self._lock:
            return self._described is None or robot in self._described

    def not_mobile(self, robot: str) -> bool:
        """Whether a sim described ``robot`` as a robot of another kind (an arm's flange pose is on ``robot/*/pose``)."""
        with self._lock:
            return robot in self._not_mobile and (self._described is None or robot not in self._described)

    def radius(self, robot: str, default: float) -> float:
        """The robot's radius from its description, else ``default``."""
        with self._lock:
            return self._radii.get(robot, default)

    def reverse(self, robot: str, default: bool) -> bool:
        """Whether the robot's description lets it drive backwards along a path (``[base] reverse``), else ``default``."""
        with self._lock:
            return self._reverse.get(robot, default)

    def learnt_offset(self, robot: str) -> Offset | None:
        """The LIDAR mounting given or learnt for ``robot`` alone (None: none), without starting a lookup."""
        with self._lock:
            return self._offsets.get(robot)

    def sensor_offset(self, robot: str) -> Offset | None:
        """The LIDAR mounting of ``robot``, or None while it is being looked up (a lookup starts if none runs)."""
        with self._lock:
            if robot in self._offsets:
                return self._offsets[robot]
            if self.sensor_offset_all is not None:
                return self.sensor_offset_all
            if not self._discover:
                return NO_OFFSET
            now = self._clock.now()
            first = self._first_seen.setdefault(robot, now)
            if self._answered_at >= first:  # the sims answered after this robot appeared, and none described it
                return NO_OFFSET
            if self._lookup.ended >= first and now - first >= UNANSWERED_S:  # no sim answers srv/world at all
                return NO_OFFSET
            self._lookup.start(1.0)  # unanswered yet (a loaded sim answers late): its scans wait, it is asked again
            return None

    # ------------------------------------------------------------------ the lookup

    def discover(self, timeout: float = 2.0) -> int:
        """Ask the sim peers' ``srv/world`` now and learn their mobile robots; returns how many were described."""
        try:
            every = described_robots(self.fabric, None, timeout=timeout)
        except ServiceError:
            return 0
        described = [r for r in every if facts(r.kind).base]
        with self._lock:
            self._answered_at = self._clock.now()
            self._not_mobile |= {r.id for r in every if not facts(r.kind).base}
            known = set(self._described or ())
            for r in described:
                known.add(r.id)
                if r.lidar is not None and r.id not in self._offsets:
                    self._offsets[r.id] = (float(r.lidar.offset[0]), float(r.lidar.offset[1]), 0.0)
                radius = float(r.base_radius or (r.base.radius if r.base is not None else 0.0))
                if radius > 0:
                    self._radii[r.id] = radius
                if r.base is not None:
                    self._reverse[r.id] = bool(r.base.reverse)
            self._described = known | set(self._followed())  # robots already followed stay
            # an arm whose flange pose came before any sim answered is followed too (it stays): not one to hear
            heard = known | (self._described - self._not_mobile)
        if self.on_described is not None:
            self.on_described(heard)
        return len(described)
