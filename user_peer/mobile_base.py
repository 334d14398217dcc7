"""A mobile base's handle: twist driving, mapping, planning and path following (:class:`Base`, kind ``mobile``)."""

from __future__ import annotations

import math
import time

from fabric import keys
from fabric.interfaces import OccupancyGrid, Path, Pose, Scan, ServiceError, Twist, yaw_from_quaternion
from user_peer import services
from user_peer.errors import NotOwner, Timeout, Unreachable
from user_peer.pause import PauseRider
from user_peer.robot import Robot

__all__ = ["Base"]


class Base(Robot):
    """A mobile base: twist driving, mapping, planning and path following."""

    kind = "mobile"
    data_stream = "pose"
    plan_note = ""
    """What the planner did to the last plan's start or goal near an obstacle ("" when nothing): an escape move
    first, a goal moved (docs/navigation.md)."""

    @property
    def pose(self) -> Pose | None:
        return self.latest("pose")

    @property
    def scan(self) -> Scan | None:
        return self.latest("scan")

    @property
    def xy_theta(self) -> tuple[float, float, float] | None:
        p = self.pose
        if p is None:
            return None
        return float(p.position[0]), float(p.position[1]), yaw_from_quaternion(p.quaternion)

    def twist(self, v: float, omega: float, *, hold: bool = True) -> None:
        """Drive at (v m/s, omega rad/s) until told otherwise, as long as this program lives and owns the base.

        The sim keeps a twist only for its deadman (0.5 s by default, docs/sim.md), so this handle repeats it
        every 0.1 s (:mod:`user_peer.deadman`) until the next twist, ``twist(0, 0)``, :meth:`stop`,
        :meth:`reset`, :meth:`follow`, :meth:`release` or the world's close. If the program dies, or the base
        passes to someone else, the repeats end and the base brakes to a halt.

        ``hold=False``: one twist, never repeated here, for a client that repeats it itself while its driver is
        there (a browser page's key held down, a bridge forwarding ROS ``cmd_vel``), so that its own silence
        stops the base within the deadman."""
        v, omega = float(v), float(omega)
        self.world.twists.drop(self.id)  # first: no resend of the twist before this one may land after it
        self._send_twist(v, omega)
        if (v or omega) and hold:
            epoch = self.record.epoch if self.record is not None else None
            self.world.twists.hold(self.id, lambda: self._send_twist(v, omega, epoch))

    def _send_twist(self, v: float, omega: float, epoch: int | None = None) -> None:
        key = keys.robot_cmd(self._w, self.id, "twist", self.world.user)
        self.send("twist", Twist(v, omega, self.world.fabric.header(key)), epoch=epoch)

    def drive(
        self, v: float, omega: float, duration: float, *, rate: float = 10.0
    ) -> tuple[float, float, float] | None:
        """Drive at (v, omega) for ``duration`` seconds (repeating the twist at ``rate`` Hz: keep it above the
        sim's deadman, 2 Hz by default), then a zero twist (the base brakes within its limits)."""
        since = self.world.event_mark()
        end = time.monotonic() + duration
        try:
            while True:
                self.twist(v, omega)
                self._check_rejected(since)
                left = end - time.monotonic()
                if left <= 0:
                    break
                time.sleep(min(left, 1.0 / rate))
        finally:
            try:
                self.twist(0.0, 0.0)
            except NotOwner:
                pass
        return self.xy_theta

    def start_mapping(self, *, name: str = "map") -> None:
        """Ask the compute peer to fold this world's scans into map ``name`` (it may already be on)."""
        try:
            services.map_request(
                self.world.fabric,
                "start",
                name=name,
                timeout=self.world.timeout,
                peer=self.world.compute_route.navigation_peer(),
                user=self.world.user,
            )
        except ServiceError as exc:
            raise Unreachable(f"mapping for {self.id}: {exc.reason}") from None

    def build_map(self, *, name: str = "map", threshold: float = 0.65, timeout: float | None = None) -> OccupancyGrid:
        """The binary map a compute peer built from the scans so far: this user's own, kept and published as
        ``map/{user}.{name}`` (:func:`fabric.keys.user_map`; the class's map is the staff's). Plan on it with
        ``plan_to(..., map_name=keys.user_map(name, world.user))``."""
        try:
            return services.build_map(
                self.world.fabric,
                name=name,
                threshold=threshold,
                timeout=timeout or max(self.world.timeout, 10.0),
                peer=self.world.compute_route.navigation_peer(),
                user=self.world.user,
            )
        except ServiceError as exc:
            raise Unreachable(f"map for {self.id}: {exc.reason}") from None

    def plan_to(
        self,
        x: float | None = None,
        y: float | None = None,
        theta: float = 0.0,
        *,
        planner: str = "hybrid_astar",
        map_name: str = "map",
        timeout: float | None = None,
        direction: str = "default",
    ) -> Path:
        """A collision-free path from the robot's pose to (x, y, theta), or to the goal object without x, y, on
        ``map_name`` (default: the class's map). A start or goal near an obstacle is recovered from, and
        :attr:`plan_note` says how. ``direction``: "default" (the base's description says whether it may reverse),
        "forward", or "both" (the path may drive backwards; the sim's follower does)."""
        goal = None if x is None or y is None else (float(x), float(y), float(theta))
        try:
            reply = services.plan_reply(
                self.world.fabric,
                self.id,
                goal,
                planner=planner,
                map_name=map_name,
                timeout=timeout or max(self.world.timeout, 15.0),
                peer=self.world.compute_route.navigation_peer(),
                user=self.world.user,
                direction=direction,
            )
            self.plan_note = reply.note
            return reply.path
        except ServiceError as exc:
            where = "the goal object" if goal is None else f"({goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.2f})"
            raise Unreachable(f"no path for {self.id} to {where}: {exc.reason}") from None

    def follow(
        self, path: Path, *, wait: bool = True, tol: float = 0.25, timeout: float = 120.0
    ) -> tuple[float, float, float] | None:
        """Send ``path`` to the sim's follower; with ``wait``, block until the base stops near its end."""
        if len(path) == 0:
            raise ValueError("cannot follow an empty path")
        events_mark, data_mark = self.world.event_mark(), self.world.latest.mark()
        self.world.twists.drop(self.id)  # the sim's follower drives now
        key = keys.robot_cmd(self._w, self.id, "path", self.world.user)
        body = Path(path.x, path.y, path.theta, path.frame, self.world.fabric.header(key))
        cmd = self.send("path", body)
        if not wait:
            return self.xy_theta
        gx, gy = float(path.x[-1]), float(path.y[-1])
        pkey = keys.robot_pose(self._w, self.id)

        def near_and_still() -> tuple[bool, bool] | None:
            p = self.world.latest.get_after(pkey, data_mark)  # a pose that arrived after the command
            if p is None:
                return None
            near = math.hypot(p.position[0] - gx, p.position[1] - gy) <= tol
            return near, math.hypot(p.linear[0], p.linear[1]) < 0.02 and abs(p.angular[2]) < 0.05

        def heard() -> bool:  # the base moves, or is at the end: the sim has the path (else it is sent again unchanged)
            seen = near_and_still()
            return seen is not None and (seen[0] or not seen[1])

        # a sim that holds its robots is ridden out; a path the base shows no sign of is sent again (its copies carry
        # its id: a sim that had it ignores them). Copies are sent only until a sign came, so never to a base under way
        rider = PauseRider(self, "path", cmd, events_mark, heard=heard)

        def arrived() -> bool:
            rider.check()
            seen = near_and_still()
            return seen is not None and seen[0] and seen[1]

        if not self.world.latest.wait_for(arrived, timeout):
            xy = self.xy_theta
            where = f"({xy[0]:.2f}, {xy[1]:.2f})" if xy else "unknown"
            raise Timeout(
                f"{self.id} did not reach the end of its path ({gx:.2f}, {gy:.2f}) within {timeout:.0f} s; it is at {where}"
                + rider.note()
            )
        return self.xy_theta
