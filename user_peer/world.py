"""The world as a user peer holds it: one Zenoh session, the cache of what the sims publish, the sims alive.

A :class:`World` joins as ``rf/{world}/peer/user/{user}`` (ownership leases rely on that token), keeps the
latest of every robot it was asked about (:class:`~user_peer.latest.Latest`), follows the sims' liveliness
and the events, and hands out robot and scene-object handles. Nothing here blocks forever: each wait has
a deadline and raises :class:`~user_peer.errors.Timeout` saying what it saw.

The rooms behind it, each an object of its own: :class:`~user_peer.description.WorldDescription` (what the
sims describe), :class:`~user_peer.presence.SimPresence` (which sims are alive, failovers),
:class:`~user_peer.event_log.EventLog` (the events and which may refuse a command),
:class:`~user_peer.following.Following` (which streams are decoded) and
:class:`~user_peer.compute_route.ComputeRoute` (which compute peer is asked).
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any, Callable, Iterable

from fabric import keys
from fabric.config import FabricConfig
from fabric.exit import at_exit
from fabric.interfaces import Event, WorldInfo
from fabric.session import Fabric
from user_peer import services
from user_peer.compute_route import ComputeRoute
from user_peer.deadman import TwistKeeper
from user_peer.description import REDESCRIBE_S, WorldDescription
from user_peer.errors import JoinFailed, Unreachable
from user_peer.event_log import EventLog
from user_peer.following import FOLLOWED_STREAMS, Following
from user_peer.latest import Latest
from user_peer.ownership_link import OwnershipLink
from user_peer.presence import FAILOVER_WAIT_S, SimPresence
from user_peer.robot import Robot, robot_status
from user_peer.scene_object import SceneObject
from user_peer.streams import StreamIterator, Subscription

__all__ = ["World", "FOLLOWED_STREAMS", "FAILOVER_WAIT_S", "REDESCRIBE_S"]


class World(contextlib.AbstractContextManager):
    """A user's handle on one world. A context manager; ``close()`` is idempotent, ``closed`` says it ran.

    ``presence`` (the sims alive, ``robots_gone``, ``failovers``), ``event_log``, ``following`` and
    ``compute_route`` are the objects behind the methods; robot handles reach them directly. Whether the
    world is there (``world_alive``, ``sims()``, ``wait_world()``, ``on_world()``, ``on_robots_gone()``,
    ``on_failover()``) is asked of ``presence``."""

    def __init__(
        self,
        config: FabricConfig,
        user: str,
        *,
        timeout: float = 5.0,
        compute: str | None = None,
        join_timeout: float | None = None,
        followed: Callable[[str], Iterable[str]] | None = None,
    ) -> None:
        self.user = keys.validate_id(config.user_id(user) or user, what="user id")  # a secure login is the user
        # the compute peer to ask (its peer id, e.g. a local one); None: the nearest that serves the world;
        # "spread": kinematics queries in turn to every live compute peer
        self.compute = None if compute is None else keys.validate_id(compute, what="compute peer id")
        self.name = config.world
        self.timeout = timeout
        # how long the first look at the world waits for a sim to serve it (a sim may start after us)
        self.join_timeout = max(timeout, 30.0) if join_timeout is None else join_timeout
        try:
            self.fabric = Fabric(config, kind="user", peer_id=self.user)
        except Exception as exc:  # zenoh.ZError: nobody there, the router refused the login, or we refused the router
            why = config.diagnose_join(exc)
            raise JoinFailed(why.text, endpoint=why.endpoint, cause=why.cause) from None
        self.closed = False
        self._close_lock = threading.Lock()
        self.robot_handles: dict[str, Robot] = {}  # the handles made so far, one per robot
        self._handles_lock = threading.Lock()  # two threads asking for a new robot at once get one handle
        self._objects: dict[str, SceneObject] = {}
        self.description = WorldDescription(
            self.fabric,
            self.name,
            live_sims=lambda: self.presence.ids(),
            timeout=timeout,
            join_timeout=self.join_timeout,
        )
        self.presence = SimPresence(self.fabric, self.name, self.description, closed=lambda: self.closed)
        self.robots_gone, self.failovers = self.presence.robots_gone, self.presence.failovers
        self.latest = Latest(world_info=lambda: self.description.current)  # keeps the robots of the description only
        self.twists = TwistKeeper()  # repeats the twists bases hold (Base.twist) against the sim's deadman
        self.compute_route = ComputeRoute(self.fabric, self.compute)
        # the latest of every scene object and map (latched: what was set before this user joined comes at
        # once); a robot's streams from its first handle on (robot())
        # ``followed(kind)``: which of FOLLOWED_STREAMS a handle of a robot of that kind keeps (every one unless told;
        # the console's pages leave a base's wheel joints out: user_peer/console/follow.py)
        self.following = Following(
            self.fabric, self.name, self.latest, None if followed is None else lambda rid: followed(self._kind(rid))
        )
        self.event_log = EventLog(
            self.user,
            live_sim=self.presence.serves,
            record=lambda obj: self.ownership.record(obj),
            then=self.latest.put,
        )
        self.events: list[Event] = self.event_log.events
        self.ownership = OwnershipLink(self.fabric, self.user, on_record=self.latest.put)
        self.fabric.subscribe(keys.event_all(self.name), self.event_log.receive, expected=Event)
        # registered after the session's own closer, so it runs first: robots are released, then the session
        # closes; a script that never calls close() exits and other users see a release, not a lease expiry
        self._cancel_exit = at_exit(self.close)
        # the sim peers serving the world, from liveliness: "world gone" is reported there (log, callbacks, world_alive)
        self.presence.watch()

    # ------------------------------------------------------------------ lifecycle

    def close(self) -> None:
        """Release every robot this user owns or waits for, then leave the world. Idempotent; also runs
        by itself when the interpreter exits (a script need not call it)."""
        with self._close_lock:
            if self.closed:
                return
            self.closed = True
        self._cancel_exit()
        self.twists.close()  # no twist goes out after this: the robots released below stop
        try:
            self.ownership.release_all(timeout=min(self.timeout, 2.0))
        finally:
            self.ownership.close()
            self.fabric.close()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        """Every robot of the world (not only those asked for) from what this world already holds: it
        makes no handle, subscribes to nothing and asks nobody. A description forgotten (a sim came back, so the
        next look asks again) still shows the last one held: "world not seen yet" is for a world never described
        (a user whose link dropped and came back at load was told it for a world he had driven in; CI, issue 49)."""
        if self.closed:
            return f"<World {self.name!r} as {self.user!r}, closed>"
        info = self.description.current or self.description.known
        if info is None:
            return f"<World {self.name!r} as {self.user!r}, world not seen yet>"
        robots = "; ".join(robot_status(self, entry) for entry in services.robot_entries(info))
        return f"<World {self.name!r} as {self.user!r}" + (f": {robots}>" if robots else ">")

    # ------------------------------------------------------------------ is the world there (self.presence)

    @property
    def world_alive(self) -> bool:
        """True while at least one sim peer of this world is alive (its liveliness token is there)."""
        return self.presence.alive

    def sims(self) -> list[str]:
        """Ids of the live sim peers of this world."""
        return self.presence.ids()

    def on_world(self, callback: Callable[[bool, str], None]) -> None:
        """``callback(alive, why)`` each time the world goes (its last sim peer left) or comes back."""
        self.presence.on_world(callback)

    def wait_world(self, *, alive: bool = True, timeout: float | None = None) -> bool:
        """Block until the world is there (``alive``) or gone; False if that did not happen within ``timeout``.

        There means serving: a restarted sim's token arrives before its services (the world description,
        ownership), and a request sent in between finds nobody to answer it; so this also waits for the
        world description, which the sim serves once its ownership authority is up."""
        return self.presence.wait(alive=alive, timeout=timeout)

    def on_failover(self, callback: Callable[[str, str, list[str]], None]) -> None:
        """``callback(sim, standby, robots)`` when the robots of a sim that left are served again by another (its
        standby took them over): told after :meth:`on_robots_gone`, within :data:`FAILOVER_WAIT_S` of the loss."""
        self.presence.on_failover(callback)

    def on_robots_gone(self, callback: Callable[[str, list[str]], None]) -> None:
        """``callback(sim, robots)`` when a sim of a world that stays alive leaves, with the robots it served (a
        world served by several sims: the others' robots go on; a standby of that sim may take them over)."""
        self.presence.on_robots_gone(callback)

    # ------------------------------------------------------------------ what is there

    def info(self, *, refresh: bool = False, timeout: float | None = None) -> WorldInfo:
        """The sim peer's world description (robots, types, limits, sensors).

        The first call waits up to ``timeout`` (default ``join_timeout``) for a sim peer to serve it, so a
        script may start before the sim; :class:`Timeout` says how long it waited and what it saw.

        The description is the union of every live sim's part (a world served by several sims); while a live
        sim describes no robot of it (a standby, which may take a shard over without any token changing, or a
        sim still starting) it is asked again at most every ``REDESCRIBE_S`` seconds.
        """
        return self.description.get(refresh=refresh, timeout=timeout)

    def _kind(self, robot_id: str) -> str:
        """The robot's kind by the description held now ("" when it is not known yet)."""
        info = self.description.current
        entry = next((r for r in services.robot_entries(info) if r.id == robot_id), None) if info else None
        return entry.kind if entry is not None else ""

    def robots(self) -> list[str]:
        """Ids of the robots in the world (from the sim's description)."""
        return sorted(r.id for r in services.robot_entries(self.info()))

    def robot(self, robot_id: str) -> Robot:
        """The robot's handle, of the class for its kind in the world description (an
        :class:`~user_peer.arm.Arm`, a :class:`~user_peer.mobile_base.Base`); one handle per robot, also when two
        threads ask at once (the console's select and request, each off its event loop). A handle already made is
        returned without the lock: only a new one waits, and may ask the world's description."""
        made = self.robot_handles.get(robot_id)
        if made is not None:
            return made
        with self._handles_lock:
            return self._robot(robot_id)

    def _robot(self, robot_id: str) -> Robot:
        if robot_id not in self.robot_handles:
            entry = next((r for r in services.robot_entries(self.info()) if r.id == robot_id), None)
            if (
                entry is None and self.description.current is not None
            ):  # a sim that joined since the description was asked for
                entry = next((r for r in services.robot_entries(self.info(refresh=True)) if r.id == robot_id), None)
            if entry is None:
                raise Unreachable(
                    f"no robot {robot_id!r} in world {self.name!r}; robots: {', '.join(self.robots()) or 'none'}"
                )
            self.robot_handles[robot_id] = Robot.for_kind(entry.kind)(self, entry)
        return self.robot_handles[robot_id]

    def object(self, object_id: str) -> SceneObject:
        """A scene object (the IK target sphere, the goal pointer): anyone may move it."""
        keys.validate_id(object_id, what="object id")
        if object_id not in self._objects:
            self._objects[object_id] = SceneObject(self, object_id)
        return self._objects[object_id]

    def compute_peers(self) -> list[str]:
        """Ids of the compute peers serving this world (from liveliness): candidates for ``compute``."""
        return self.compute_route.peers()

    # ------------------------------------------------------------------ streams and events

    def on(self, key_expr: str, callback: Callable[[str, Any], None]) -> Subscription:
        """Call ``callback(key, message)`` for each message on ``key_expr`` (relative keys get ``rf/WORLD/``)."""
        return Subscription(self.fabric, keys.in_world(key_expr, self.name), callback)

    def stream(self, key_expr: str, *, timeout: float | None = 5.0, limit: int | None = None) -> StreamIterator:
        """Iterate over messages on ``key_expr``; stops after ``timeout`` s of silence or ``limit`` messages."""
        return StreamIterator(self.fabric, keys.in_world(key_expr, self.name), timeout=timeout, limit=limit)

    def event_mark(self) -> int:
        """How many events have arrived so far: pass it to :meth:`rejections` to see only later ones."""
        return self.event_log.mark()

    def rejections(self, robot: str, since: int) -> list[Event]:
        """Events refusing this user's commands to ``robot`` that arrived after ``since`` (an
        :meth:`event_mark`). Judged by arrival here, never by the sender's clock. Only the robot's
        authority can refuse (:meth:`EventLog.from_authority`): a forged ``reject`` on a key any login may
        write is display-only."""
        return self.event_log.rejections(robot, since)

    def recent_events(self, limit: int = 20) -> list[tuple[Event, bool]]:
        """The latest ``limit`` events, oldest first, each with whether it came from its object's authority
        (False: display-only, e.g. a decode report any login may write; the TUI marks those)."""
        return self.event_log.recent(limit)
