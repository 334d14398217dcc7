"""Bases that meet do not collide: a base following a path slows and stops before what its LIDAR sees in its way.

A path is planned on a map, and maps hold the world, not the robots in it (docs/navigation.md): another base, or
anything new, may stand on it. While a base follows a path, every :data:`GUARD_PERIOD` of sim time its
:class:`WayGuard` reads the LIDAR and finds the **gap**: how far along the path the base can go before its disk
(radius less :data:`SLACK`) would touch a LIDAR hit (:func:`way_gap`). The follower's speed is then capped so that
the base can brake within the gap less :data:`WAY_MARGIN` at half its deceleration (:func:`way_cap`,
v = sqrt(a d)); a base whose cap
reaches zero waits, says so (``Event(kind=obstacle_stop, reason="waiting")``), goes on when the way clears
(``resumed``), or, after :data:`BLOCKED_AFTER` seconds, drops the path, backs off :data:`BACK_OFF` along the way it
came (:func:`trail_back`) and reports ``blocked`` so that its user can plan again (:func:`decide`, pure: time
passed in). Two bases driving at each other both stop, apart.

The bases of one sim share a board (:mod:`sim_peer.physics.traffic`): each guard also checks the other bases all around,
where they stand (:func:`base_gap`: never nearer than their radii plus :data:`BASE_CLEARANCE`) and where they go
(:func:`~sim_peer.physics.traffic.crossing`: of two bases whose ways meet, the one further from the meeting waits short of
the other's way), and names the base in its way. The LIDAR looks ahead (the Reeman's: 135 degrees): what it
cannot see, other than the sim's own bases, is left to the bumper (a base driving backwards, a robot of another sim
coming from the side). Bases that wait for each other do not wait for ever: after
:data:`~sim_peer.physics.traffic.GIVE_WAY_AFTER` one of them gives way (it reports ``blocked`` at once, naming the other).
Hits on static walls never stop a base on a planned path: the planner keeps its paths a radius from the map's
obstacles, and the check uses the radius less :data:`SLACK` (the planner's cells are 5 cm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from fabric.interfaces import EventKind
from sim_peer.physics.pure_pursuit import PurePursuit
from sim_peer.robot import Note, Physics
from sim_peer.sensors import Sensor
from sim_peer.physics.traffic import Spot, Traffic, Waiter, crossing, gives_way, yields

if TYPE_CHECKING:
    from sim_peer.physics.robot_kinds import MobileRobot

__all__ = [
    "BACK_OFF",
    "BASE_CLEARANCE",
    "BLOCKED_AFTER",
    "GUARD_PERIOD",
    "SLACK",
    "WAY_MARGIN",
    "WayGuard",
    "WayState",
    "decide",
    "base_gap",
    "facing_forwards",
    "trail_back",
    "way_cap",
    "way_gap",
]

GUARD_PERIOD = 0.05
"""Seconds of sim time between two looks (the LIDAR's own stream runs at 10-20 Hz)."""
WAY_MARGIN = 0.15
"""Metres a base keeps between its disk and what is in its way when it stops."""
RESUME = 0.05
"""Metres beyond the margin the way must clear before a waiting base goes on (no stutter at the edge)."""
BLOCKED_AFTER = 10.0
"""Seconds of sim time a base waits before it drops its path and reports ``blocked``."""
SLACK = 0.05
"""Metres taken off the radius in the check: the planner keeps paths a radius from its cells' centres, and a wall's
face may lie up to half a cell nearer."""
BASE_CLEARANCE = 0.05
"""Metres kept between two bases' disks (their radii about the turn point) on top of the radii: a bumper looks up to
4 cm beyond the disk ahead (its shell, 1 cm, and a period's travel), so bases kept only their radii apart met on
the bumper. Plans mark other robots 0.1 m beyond their radius (``compute_peer.navigation.plan_service``), so a
path planned past a base standing still is clear of this."""
LOOK = 2.0
"""Metres of path ahead that are checked (more than the braking distance at 1 m/s plus the margin)."""
BACK_OFF = 0.4
"""Metres a base whose way stayed blocked, or that gives way, backs off along the way it came before it says
``blocked``: room to turn for the plan its user makes next (stopped 0.15 m short, facing what is in its way, a base
that drives forwards only has no first move)."""
BACK_SPEED = 0.2
"""m/s of a back-off (driven backwards: what is behind is where it came from, and the sim's other bases)."""


def trail_back(points: np.ndarray, index: int, here: np.ndarray, length: float = BACK_OFF) -> np.ndarray | None:
    """The way a base came along its path ``points`` ((n, 2), progress ``index``): from ``here`` back ``length``
    metres through the points before its progress; None when that is under a tenth of ``length``."""
    behind = points[:index][::-1]
    behind = behind[np.hypot(*(behind - here).T) > 0.02] if behind.shape[0] else behind
    trail = np.vstack([here, behind])
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(trail, axis=0).T))])
    if cum[-1] < 0.1 * length:
        return None
    end = int(np.searchsorted(cum, length))
    if end >= trail.shape[0]:
        return trail
    t = (length - cum[end - 1]) / (cum[end] - cum[end - 1])
    return np.vstack([trail[:end], trail[end - 1] + t * (trail[end] - trail[end - 1])])


def facing_forwards(trail: np.ndarray, yaw: float) -> np.ndarray:
    """Headings along a trail driven backwards: at each point the way the path ran (from it to the point before),
    ``yaw`` at the first; what makes :class:`~sim_peer.physics.pure_pursuit.PurePursuit` drive it backwards."""
    d = trail[:-1] - trail[1:]
    return np.concatenate([[yaw], np.arctan2(d[:, 1], d[:, 0])])


def way_gap(path: np.ndarray, hits: np.ndarray, radius: float) -> float:
    """Arc length along ``path`` ((n, 2), from where the base is) before a disk of ``radius`` about it would hold
    one of ``hits`` ((m, 2)); ``inf`` when none does. Hits within the disk where the base stands are left out: it
    stands there already (a start that escapes from beside a wall), and a touch is the bumper's business."""
    if path.shape[0] < 2 or hits.shape[0] == 0:
        return math.inf
    r2 = radius * radius
    hits = hits[((hits - path[0]) ** 2).sum(axis=1) > r2]
    if hits.shape[0] == 0:
        return math.inf
    d2 = ((path[:, None, :] - hits[None, :, :]) ** 2).sum(axis=2)
    touching = np.flatnonzero((d2 <= r2).any(axis=1))
    if touching.size == 0:
        return math.inf
    first = int(touching[0])  # >= 1: the disk at path[0] holds no hit
    return float(np.hypot(np.diff(path[:first, 0]), np.diff(path[:first, 1])).sum())  # to the last clear point


def base_gap(path: np.ndarray, centre: tuple[float, float], radius: float) -> float:
    """Arc length along ``path`` ((n, 2), from where the base is) before it comes nearer than ``radius`` to another
    base's ``centre``, or, where it stands nearer already, nearer than it stands; ``inf`` when it never does.

    Unlike a LIDAR hit (:func:`way_gap`), another base within the radius is not left to the bumper: it may have
    come from the side, unseen by the path's disks ahead until it was within them (two bases crossing in the gap
    both stopped 0.10 m short by the path and bumped, centres 0.59 m apart). A base that stands that near may move
    away from it, never towards it. Pure: the board's spot in, metres out."""
    if path.shape[0] < 2:
        return math.inf
    d = np.hypot(path[:, 0] - centre[0], path[:, 1] - centre[1])
    closer = np.flatnonzero(d[1:] < min(radius, d[0] - 1e-9)) + 1
    if closer.size == 0:
        return math.inf
    first = int(closer[0])
    return float(np.hypot(np.diff(path[:first, 0]), np.diff(path[:first, 1])).sum())  # to the last point not nearer


def way_cap(gap: float, accel: float, margin: float = WAY_MARGIN) -> float:
    """The speed from which a base braking at half its ``accel`` stops ``margin`` short of what is ``gap`` ahead.

    Half: the controller brakes at its full limit, so a base that keeps to this cap stops within half the gap,
    which leaves the other half to a base coming the other way (both see the same gap), and some to the
    guard's period (the cap is a look :data:`GUARD_PERIOD` old)."""
    if math.isinf(gap):
        return math.inf
    return math.sqrt(accel * max(gap - margin, 0.0))


@dataclass(frozen=True, slots=True)
class WayState:
    """Since when (sim time) the base has waited for its way to clear; None while it moves."""

    waiting_since: float | None = None


def decide(
    state: WayState, now: float, gap: float, *, margin: float = WAY_MARGIN, blocked_after: float = BLOCKED_AFTER
) -> tuple[WayState, str]:
    """The next state and what to say: "" (nothing new), "waiting" (the way closed: stopped), "resumed" (it
    cleared), "blocked" (it stayed closed ``blocked_after`` s: drop the path)."""
    if state.waiting_since is None:
        if gap <= margin:
            return WayState(now), "waiting"
        return state, ""
    if gap > margin + RESUME:
        return WayState(None), "resumed"
    if now - state.waiting_since >= blocked_after:
        return WayState(None), "blocked"
    return state, ""


_WORDS = {
    "waiting": "stopped before something in its way; goes on when it clears",
    "resumed": "the way cleared: following the path again",
    "blocked": "its way stayed blocked: the path is dropped (plan again)",
}
BLAME = 0.2
"""Metres: a base whose disk closes the way this near the LIDAR's gap is named as what is in the way."""


class WayGuard(Sensor):
    """The guard of one mobile robot with a LIDAR: caps its path follower's speed (``BaseController.speed_cap``)."""

    def __init__(
        self,
        robot: "MobileRobot",
        dt: float,
        *,
        margin: float = WAY_MARGIN,
        blocked_after: float = BLOCKED_AFTER,
        traffic: Traffic | None = None,
    ) -> None:
        self.robot = robot
        self.traffic = traffic if traffic is not None else Traffic()
        self.every = max(1, int(round(GUARD_PERIOD / dt)))
        self.margin = margin
        self.blocked_after = blocked_after
        self.radius = (
            max(robot.desc.base.radius if robot.desc.base is not None else robot.desc.base_radius, 0.0) - SLACK
        )
        self.state = WayState()
        self.gap = math.inf  # the last gap seen (for tests and the sim's state)
        self.blocker: str | None = None  # the base in its way at the last look, if a base is
        self.full_radius = self.radius + SLACK
        self._backing: tuple[object, str | None] | None = None  # the back-off under way, and whom it gave way to

    def _path_ahead(self, follower) -> np.ndarray:
        """The base's position, then the follower's path points from its progress up to :data:`LOOK` along."""
        c = self.robot.ctrl
        i = follower.index
        cum = follower.cumulative
        end = int(np.searchsorted(cum, cum[i] + LOOK, side="right"))
        return np.vstack([[c.x, c.y], follower.points[i + 1 : max(end, i + 2)]])

    def _hits(self, physics: Physics) -> np.ndarray:
        """The LIDAR's hits in the world frame, read now: positions first made current (a world of kinematic
        robots leaves them to the next read, and the other bases have moved since)."""
        lidar = self.robot.lidar
        mujoco.mj_kinematics(physics.model, physics.data)
        ranges = lidar.read(physics.data)
        hit = ranges < lidar.spec.range_max - 1e-6
        site = physics.data.site_xpos[lidar.site_id]
        rot = physics.data.site_xmat[lidar.site_id].reshape(3, 3)
        a = lidar.angles[hit]
        local = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)]) * ranges[hit, None]
        return (site + local @ rot.T)[:, :2]

    def _gap(self, path: np.ndarray, physics: Physics) -> tuple[float, str | None]:
        """The gap ahead (the LIDAR's, or the sim's other bases' disks where they stand) and the base that closes
        it, if a base does."""
        gap = way_gap(path, self._hits(physics), self.radius)
        nearest, blocker = math.inf, None
        x, y = path[0]
        me, board = self.robot.id, self.traffic.yielding
        before = board.pop(me, None)  # the base it let through at the last look: chosen again while their ways meet
        for rid, spot in self.traffic.others(self.robot.id).items():
            reach = self.full_radius + spot.radius + BASE_CLEARANCE  # no map cells: no slack, and the bumper's reach
            if math.hypot(spot.x - x, spot.y - y) > 2 * LOOK + reach:
                continue  # beyond both ways looked at
            g = base_gap(path, (spot.x, spot.y), reach)
            meet = crossing(path, np.array(spot.way), reach) if spot.way else None
            held = {k: v for k, v in ((rid, board.get(rid)), (me, before)) if v is not None}
            if meet is not None and yields(me, meet[0], rid, meet[1], held):
                board[me] = rid
                g = min(g, meet[0])  # both head for one place and it gets there first: wait short of its way
            if g < nearest:
                nearest, blocker = g, rid
        return min(gap, nearest), (blocker if nearest <= gap + BLAME else None)

    def after_step(self, physics: Physics) -> None:
        c, rid = self.robot.ctrl, self.robot.id
        follower = c.follower
        ahead = self._path_ahead(follower) if follower is not None and hasattr(follower, "points") else None
        way = tuple(map(tuple, ahead.tolist())) if ahead is not None else ()
        self.traffic.stand(rid, Spot(c.x, c.y, self.full_radius, way))
        if self._backing is not None:
            self._back_off(physics)
            return
        if follower is None or not hasattr(follower, "points"):
            c.speed_cap = math.inf
            self.traffic.wait(rid, None)
            self.traffic.yielding.pop(rid, None)  # no way: it lets nobody through
            if self.state.waiting_since is not None:
                self.state = WayState()
            return
        self.gap, self.blocker = self._gap(ahead, physics)
        c.speed_cap = way_cap(self.gap, c.spec.max_accel, self.margin)
        self.state, news = decide(
            self.state, physics.time, self.gap, margin=self.margin, blocked_after=self.blocked_after
        )
        since = self.state.waiting_since
        if since is not None:  # a waiting base holds (it may turn on the spot) until it says resumed: no creeping
            c.speed_cap = 0.0  # within the resume band (two waiting bases crept 0.1 m each into the bumper's reach)
        self.traffic.wait(rid, None if since is None else Waiter(since, self.blocker))
        to = gives_way(self.traffic.waiters, rid, physics.time) if since is not None else None
        if to is not None:  # it and the bases it waits for wait for each other: this one gives way
            self.state, news = WayState(), "blocked"
        if news == "blocked":
            self.traffic.wait(rid, None)
            c.brake()
            c.speed_cap = math.inf
            trail = trail_back(follower.points, follower.index, np.array([c.x, c.y]))
            if trail is not None:  # first back off, then say it
                b = self.robot.desc.base
                back = PurePursuit(
                    trail[:, 0],
                    trail[:, 1],
                    facing_forwards(trail, c.yaw),
                    max_speed=min(BACK_SPEED, b.max_speed),
                    max_omega=b.max_omega,
                    max_accel=b.max_accel,
                )
                back.quiet = True  # type: ignore[attr-defined]  # its end is no path of the user's done
                c.follow(back)
                self._backing = (back, to)
                return
        if news:
            self._say(news, physics, to)

    def _back_off(self, physics: Physics) -> None:
        """A back-off under way: it goes on while its way is clear; once done, closed, or replaced by a command,
        the base says ``blocked``."""
        c = self.robot.ctrl
        back, to = self._backing  # type: ignore[misc]
        if c.follower is back:
            gap, _ = self._gap(self._path_ahead(back), physics)
            c.speed_cap = way_cap(gap, c.spec.max_accel, self.margin)
            if gap > self.margin:
                return
            c.brake()
            c.speed_cap = math.inf
        self._backing = None
        self._say("blocked", physics, to, backed=True)

    def _say(self, news: str, physics: Physics, to: str | None, *, backed: bool = False) -> None:
        c = self.robot.ctrl
        words = f"gave way to {to}, which waits for it: the path is dropped (plan again)" if to else _WORDS[news]
        if news == "waiting" and self.blocker is not None:
            words = f"stopped before {self.blocker} in its way; goes on when it clears"
        if backed:
            words += "; backed off along the way it came"
        detail = f"{words} (gap {self.gap:.2f} m at ({c.x:.2f}, {c.y:.2f}))" if math.isfinite(self.gap) else words
        data = {
            "t": physics.time,
            "detail": detail,
            **({"gave_way_to": to} if to else {}),
            **({"blocker": self.blocker} if self.blocker and news == "waiting" else {}),
        }
        self.robot.note(
            Note(
                EventKind.OBSTACLE_STOP,
                news,
                "warning" if news != "resumed" else "info",
                data,
                counter="way_gave_way" if to else f"way_{news}",
            )
        )
