"""The world as a user peer holds it: one Zenoh session, the cache of what the sims publish, the sims alive.

A :class:`World` joins as ``rf/{world}/peer/user/{user}`` (ownership leases rely on that token), keeps the
latest of every robot it was asked about (:class:`~user_peer.latest.Latest`), follows the sims' liveliness
and the events, and hands out robot and scene-object handles. Nothing here blocks forever: each wait has
a deadline and raises :class:`~user_peer.errors.Timeout` saying what it saw.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

from fabric import keys
from fabric.config import FabricConfig
from fabric.exit import at_exit
from fabric.fencing import is_authority_event
from fabric.interfaces import REJECT_KINDS, Event, ServiceError, WorldInfo
from fabric.session import Fabric
from user_peer import services
from user_peer.deadman import TwistKeeper
from user_peer.errors import JoinFailed, Timeout, Unreachable
from user_peer.latest import Latest
from user_peer.ownership_link import OwnershipLink
from user_peer.robot import Robot, robot_status
from user_peer.scene_object import SceneObject
from user_peer.spread import SPREAD, RoundRobin
from user_peer.streams import StreamIterator, Subscription

log = logging.getLogger("robofabric.user")

__all__ = ["World", "FOLLOWED_STREAMS"]


REDESCRIBE_S = 1.0
"""How often :meth:`World.info` asks again while a live sim describes no robot of the world (a standby)."""

FAILOVER_WAIT_S = 15.0
"""How long after a sim left :meth:`World.on_failover` waits for another sim (its standby) to serve its robots:
a standby takes over within its leader's token loss plus a transport lease (docs/sim.md)."""

FOLLOWED_STREAMS = ("joints", "pose", "scan", "path", "ik")
"""The streams a robot handle keeps the latest of (:meth:`World.robot`)."""


class World:
    """A user's handle on one world. A context manager; ``close()`` is idempotent."""

    def __init__(
        self, config: FabricConfig, user: str, *, timeout: float = 5.0, compute: str | None = None,
        join_timeout: float | None = None,
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
        self._info: WorldInfo | None = None
        self._known: WorldInfo | None = None  # the last description seen (which robots a departed sim served)
        self._info_at = 0.0  # when it was asked for (monotonic)
        self.latest = Latest(world_info=lambda: self._info)  # keeps the robots of the description only
        self.events: list[Event] = []
        # (local arrival number, event, trusted): trusted when a sim-only key carried it from the object's
        # authority (_from_authority); only those can refuse a command here, the rest is display-only
        self._event_log: list[tuple[int, Event, bool]] = []
        self.untrusted_events = 0  # events acted on by nothing: any login may write their keys, or not the authority's
        self._events_seen = 0
        self._events_lock = threading.Lock()
        self._closed = False
        self._robots: dict[str, Robot] = {}
        self.twists = TwistKeeper()  # repeats the twists bases hold (Base.twist) against the sim's deadman
        self._objects: dict[str, SceneObject] = {}
        # the latest of every scene object and map (latched: what was set before this user joined comes at
        # once); a robot's streams are followed from its first handle on (robot()): a student of a class
        # decodes her own robots' streams, not the whole world's (32 robots: ~4,600 messages a second each)
        self._followed: set[str] = set()
        # every writer's pose of an object is kept under the object's reader key (object/{id}/pose/by/*)
        self.fabric.subscribe(keys.object_pose_all(self.name), self._on_object_pose, history=True)
        self.fabric.subscribe(f"{keys.world_root(self.name)}/map/*", self.latest.put, history=True)
        self.fabric.subscribe(keys.event_all(self.name), self._on_event, expected=Event)
        self.ownership = OwnershipLink(self.fabric, self.user, on_record=self.latest.put)
        self._spread = RoundRobin(self.compute_peers) if self.compute == SPREAD else None
        # registered after the session's own closer, so it runs first: robots are released, then the session
        # closes; a script that never calls close() exits and other users see a release, not a lease expiry
        self._cancel_exit = at_exit(self.close)
        # the sim peers serving the world, from liveliness: one that dies is seen at once, one cut off or
        # frozen within the transport lease; "world gone" is reported here (log, callbacks, world_alive)
        self._sims: set[str] = set()
        self.robots_gone: list[str] = []  # robots whose sim left while others serve the world (on_robots_gone)
        self.failovers: list[tuple[str, str, list[str]]] = []  # (sim, the sim that took its robots, robots): on_failover
        self._failover_callbacks: list[Callable[[str, str, list[str]], None]] = []
        self._gone_callbacks: list[Callable[[str, list[str]], None]] = []
        self._world_callbacks: list[Callable[[bool, str], None]] = []
        self._world_seen = False
        self._world_cond = threading.Condition()
        self.fabric.watch_peers(self._on_sim, kind="sim")

    def ask_kinematics(self, call: Callable[[str | None], Any]) -> Any:
        """``call(peer)`` with the compute peer for the next kinematics query: the chosen one, the next in
        turn (``compute="spread"``), or None (the nearest). A spread peer that left since the list was read
        is skipped and the nearest asked instead, so a peer going away costs one timeout, not an error."""
        if self._spread is None:
            return call(self.compute)
        peer = self._spread.next()
        try:
            return call(peer)
        except ServiceError as exc:
            if peer is None or not exc.reason.startswith("no reply"):
                raise
            self._spread.forget(peer)
            return call(None)

    def navigation_peer(self) -> str | None:
        """The compute peer for maps and plans: the chosen one, else the nearest (a map is not spread)."""
        return None if self.compute == SPREAD else self.compute

    def compute_peers(self) -> list[str]:
        """Ids of the compute peers serving this world (from liveliness): candidates for ``compute``."""
        return sorted(pid for _, pid in self.fabric.live_peers("compute"))

    # ------------------------------------------------------------------ lifecycle

    def close(self) -> None:
        """Release every robot this user owns or waits for, then leave the world. Idempotent; also runs
        by itself when the interpreter exits (a script need not call it)."""
        with self._events_lock:
            if self._closed:
                return
            self._closed = True
        self._cancel_exit()
        self.twists.close()  # no twist goes out after this: the robots released below stop
        try:
            self.ownership.release_all(timeout=min(self.timeout, 2.0))
        finally:
            self.ownership.close()
            self.fabric.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> "World":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        """Every robot of the world (not only those asked for) from what this world already holds: it
        makes no handle, subscribes to nothing and asks nobody."""
        if self._closed:
            return f"<World {self.name!r} as {self.user!r}, closed>"
        info = self._info
        if info is None:
            return f"<World {self.name!r} as {self.user!r}, world not seen yet>"
        robots = "; ".join(robot_status(self, entry) for entry in services.robot_entries(info))
        return f"<World {self.name!r} as {self.user!r}" + (f": {robots}>" if robots else ">")

    # ------------------------------------------------------------------ is the world there

    @property
    def world_alive(self) -> bool:
        """True while at least one sim peer of this world is alive (its liveliness token is there)."""
        with self._world_cond:
            return bool(self._sims)

    def sims(self) -> list[str]:
        """Ids of the live sim peers of this world."""
        with self._world_cond:
            return sorted(self._sims)

    def on_world(self, callback: Callable[[bool, str], None]) -> None:
        """``callback(alive, why)`` each time the world goes (its last sim peer left) or comes back."""
        with self._world_cond:
            self._world_callbacks.append(callback)

    def wait_world(self, *, alive: bool = True, timeout: float | None = None) -> bool:
        """Block until the world is there (``alive``) or gone; False if that did not happen within ``timeout``.

        There means serving: a restarted sim's token arrives before its services (the world description,
        ownership), and a request sent in between finds nobody to answer it; so this also waits for the
        world description, which the sim serves once its ownership authority is up."""
        deadline = time.monotonic() + (self.join_timeout if timeout is None else timeout)
        with self._world_cond:
            while bool(self._sims) != alive:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._world_cond.wait(min(left, 0.1))
        if not alive:
            return True
        try:
            self._info = self._fetch_description(max(0.0, deadline - time.monotonic()))
        except Timeout:
            return False
        return True

    def _on_sim(self, kind: str, peer_id: str, alive: bool) -> None:
        with self._world_cond:
            was = bool(self._sims)
            changed = alive != (peer_id in self._sims)
            (self._sims.add if alive else self._sims.discard)(peer_id)
            now = bool(self._sims)
            first, self._world_seen = now and not self._world_seen, self._world_seen or now
            callbacks = list(self._world_callbacks) if now != was else []
            self._world_cond.notify_all()
        if changed and now == was:
            self._sims_changed(peer_id, alive)
        if now == was:
            return
        # "is back" only after the world was there and went: at a start, the first sim is simply there
        why = (f"sim peer {peer_id} serves world {self.name!r}" if first else f"sim peer {peer_id} is back" if now
               else f"world {self.name!r} gone: its sim peer {peer_id} left (died, or cut off)")
        if now:
            self._info = None  # a restarted sim may describe a different world: ask again
            log.info("world %s: %s", self.name, why)
        else:
            log.warning("%s", why)
        for cb in callbacks:
            try:
                cb(now, why)
            except Exception:
                log.exception("world callback failed")

    def _sims_changed(self, peer_id: str, alive: bool) -> None:
        """Another sim of a world that stays alive came or went: the description is asked again (a shard's
        robots join or leave it), and the robots a departed sim served are named (``robots_gone``)."""
        info = self._info or self._known
        self._info = None  # robots() / robot() ask every sim again
        if alive or info is None:
            return
        gone = sorted(r.id for r in info.robots if r.sim == peer_id)
        if not gone:
            return  # a standby, or a sim that served nothing we saw
        with self._events_lock:
            self.robots_gone.extend(gone)
            callbacks = list(self._gone_callbacks)
        log.warning("robots %s gone from world %s: their sim peer %s left (died, or cut off); the other sims' robots go on",
                    ", ".join(gone), self.name, peer_id)
        for cb in callbacks:
            try:
                cb(peer_id, gone)
            except Exception:
                log.exception("robots-gone callback failed")
        # a standby of that sim (a live sim serving nothing yet) takes them over within its lease: say so when it does
        threading.Thread(target=self._watch_failover, args=(peer_id, gone), name="world-failover", daemon=True).start()

    def _watch_failover(self, sim: str, robots: list[str]) -> None:
        """Ask the world's description until another sim serves every robot ``sim`` served, for up to
        :data:`FAILOVER_WAIT_S`; then tell it as ``sim X failed over to Y`` (log, ``failovers``, :meth:`on_failover`).
        Without this, a standby's take-over reached scripts only as "robots ... gone from world"."""
        deadline = time.monotonic() + FAILOVER_WAIT_S
        while not self._closed and time.monotonic() < deadline:
            with self._world_cond:
                if sim in self._sims:
                    return  # the same sim came back (a pause): not a failover
            try:
                info = services.world_info(self.fabric, timeout=1.0)
            except Exception:  # no sim answers now (the standby is taking over), or the session closed
                info = None
            if info is not None:
                served = {r.id: r.sim for r in info.robots}
                takers = sorted({served[r] for r in robots if served.get(r) not in (None, "", sim)})
                if takers and all(served.get(r) not in (None, "", sim) for r in robots):
                    self._failed_over(sim, ", ".join(takers), robots)
                    return
            time.sleep(0.25)

    def _failed_over(self, sim: str, to: str, robots: list[str]) -> None:
        with self._events_lock:
            self.failovers.append((sim, to, list(robots)))
            callbacks = list(self._failover_callbacks)
        log.warning("sim %s failed over to %s: robots %s go on in world %s", sim, to, ", ".join(robots), self.name)
        for cb in callbacks:
            try:
                cb(sim, to, list(robots))
            except Exception:
                log.exception("failover callback failed")

    def on_failover(self, callback: Callable[[str, str, list[str]], None]) -> None:
        """``callback(sim, standby, robots)`` when the robots of a sim that left are served again by another (its
        standby took them over): told after :meth:`on_robots_gone`, within :data:`FAILOVER_WAIT_S` of the loss."""
        with self._events_lock:
            self._failover_callbacks.append(callback)

    def on_robots_gone(self, callback: Callable[[str, list[str]], None]) -> None:
        """``callback(sim, robots)`` when a sim of a world that stays alive leaves, with the robots it served (a
        world served by several sims: the others' robots go on; a standby of that sim may take them over)."""
        with self._events_lock:
            self._gone_callbacks.append(callback)

    # ------------------------------------------------------------------ what is there

    def info(self, *, refresh: bool = False, timeout: float | None = None) -> WorldInfo:
        """The sim peer's world description (robots, types, limits, sensors).

        The first call waits up to ``timeout`` (default ``join_timeout``) for a sim peer to serve it, so a
        script may start before the sim; :class:`Timeout` says how long it waited and what it saw.

        The description is the union of every live sim's part (a world served by several sims); while a live
        sim describes no robot of it (a standby, which may take a shard over without any token changing, or a
        sim still starting) it is asked again at most every ``REDESCRIBE_S`` seconds.
        """
        if self._info is None or refresh:
            self._info = self._fetch_description(self.join_timeout if timeout is None else timeout)
        elif time.monotonic() - self._info_at > REDESCRIBE_S and self._undescribed_sims(self._info):
            self._info_at = time.monotonic()
            try:
                self._info = self._fetch_description(min(1.0, self.timeout))
            except (Timeout, Unreachable):
                pass  # keep what we had: the world's own trouble is reported by its tokens
        return self._info

    def _undescribed_sims(self, info: WorldInfo) -> bool:
        """Whether a live sim serves no robot of ``info`` (a standby, or a sim whose part is not in yet)."""
        described = {r.sim for r in info.robots}
        with self._world_cond:
            return bool(self._sims - described)

    def _fetch_description(self, wait: float) -> WorldInfo:
        """The world description, asked again until a sim serves it or ``wait`` s pass: the one wait for the
        world that :meth:`info` and :meth:`wait_world` share. :class:`Timeout` names the sims alive and the
        last answer; a sim that refuses to describe its world is :class:`Unreachable` at once."""
        key = keys.srv(self.name, "world")
        t0 = time.monotonic()
        deadline = t0 + wait
        last = ""
        while True:
            left = deadline - time.monotonic()
            try:
                # at most a few seconds per try: a query sent before any sim existed is never answered later
                info = services.world_info(self.fabric, timeout=max(0.05, min(left, 2.0)))
                self._known = info
                self._info_at = time.monotonic()
                return info
            except ServiceError as exc:
                if not exc.reason.startswith("no reply"):
                    raise Unreachable(f"the sim of world {self.name!r} refused its description: {exc.reason}") from None
                last = exc.reason
            left = deadline - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(0.2, left))  # no queryable yet: zenoh answers at once, so pace the retries
        sims = sorted(pid for _, pid in self.fabric.live_peers("sim", timeout=0.5))
        seen = f"sim peers alive: {', '.join(sims)}" if sims else "no sim peer alive in this world"
        raise Timeout(
            f"no world description for {self.name!r} after {time.monotonic() - t0:.1f} s of waiting: "
            f"nobody served {key} ({seen}; last answer: {last}). Is a sim peer running on world {self.name!r}?"
        )

    def robots(self) -> list[str]:
        """Ids of the robots in the world (from the sim's description)."""
        return sorted(r.id for r in services.robot_entries(self.info()))

    def robot(self, robot_id: str) -> Robot:
        """The robot's handle, of the class for its kind in the world description (an
        :class:`~user_peer.robot.Arm`, a :class:`~user_peer.robot.Base`); one handle per robot."""
        if robot_id not in self._robots:
            entry = next((r for r in services.robot_entries(self.info()) if r.id == robot_id), None)
            if entry is None and self._info is not None:  # a sim that joined since the description was asked for
                entry = next((r for r in services.robot_entries(self.info(refresh=True)) if r.id == robot_id), None)
            if entry is None:
                raise Unreachable(f"no robot {robot_id!r} in world {self.name!r}; robots: {', '.join(self.robots()) or 'none'}")
            self._robots[robot_id] = Robot.for_kind(entry.kind)(self, entry)
        return self._robots[robot_id]

    def keep_latest(self, robot_id: str) -> bool:
        """Keep the latest of ``robot_id``'s streams from now on; True the first time it is asked for the robot
        (a :class:`Robot` handle asks, once per robot) (ik: a compute peer's streamed IK, Test A); paths are
        latched (a path planned before the handle comes at once)."""
        if robot_id in self._followed:
            return False
        self._followed.add(robot_id)
        for stream in FOLLOWED_STREAMS:
            self.fabric.subscribe(keys.robot_stream(self.name, robot_id, stream), self.latest.put, history=stream == "path")
        return True

    def _on_object_pose(self, key: str, msg: Any) -> None:
        self.latest.put(keys.object_pose_all(self.name, keys.parse(key).subject), msg)

    def object(self, object_id: str) -> SceneObject:
        """A scene object (the IK target sphere, the goal pointer): anyone may move it."""
        keys.validate_id(object_id, what="object id")
        if object_id not in self._objects:
            self._objects[object_id] = SceneObject(self, object_id)
        return self._objects[object_id]

    # ------------------------------------------------------------------ streams

    def on(self, key_expr: str, callback: Callable[[str, Any], None]) -> Subscription:
        """Call ``callback(key, message)`` for each message on ``key_expr`` (relative keys get ``rf/WORLD/``)."""
        return Subscription(self.fabric, self._abs(key_expr), callback)

    def stream(self, key_expr: str, *, timeout: float | None = 5.0, limit: int | None = None) -> StreamIterator:
        """Iterate over messages on ``key_expr``; stops after ``timeout`` s of silence or ``limit`` messages."""
        return StreamIterator(self.fabric, self._abs(key_expr), timeout=timeout, limit=limit)

    def _abs(self, key_expr: str) -> str:
        return keys.in_world(key_expr, self.name)

    def _from_authority(self, key: str, ev: Event) -> bool:
        """Whether ``ev`` may change what this user's program does: it came on a key only sims may write
        (``fabric.fencing.is_authority_event``; never ``event/decode/by/*``, which any login writes) from a
        live sim that is the authority of the object it names (its ownership record's ``authority``)."""
        if not is_authority_event(key):
            return False
        source = ev.header.source
        if source not in getattr(self, "_sims", ()):  # (events may come before __init__ is done: untrusted)
            return False
        link = getattr(self, "ownership", None)
        rec = link.record(ev.object) if link is not None and ev.object else None
        return rec is None or rec.authority == source

    def _on_event(self, key: str, ev: Event) -> None:
        trusted = self._from_authority(key, ev)
        with self._events_lock:
            self._events_seen += 1
            self.events.append(ev)
            self._event_log.append((self._events_seen, ev, trusted))
            if not trusted:
                self.untrusted_events += 1
            if len(self.events) > 1000:
                del self.events[:500]
                del self._event_log[:500]
        self.latest.put(key, ev)

    def event_mark(self) -> int:
        """How many events have arrived so far: pass it to :meth:`rejections` to see only later ones."""
        with self._events_lock:
            return self._events_seen

    def rejections(self, robot: str, since: int) -> list[Event]:
        """Events refusing this user's commands to ``robot`` that arrived after ``since`` (an
        :meth:`event_mark`). Judged by arrival here, never by the sender's clock. Only the robot's
        authority can refuse (:meth:`_from_authority`): a forged ``reject`` on a key any login may write is
        display-only."""
        with self._events_lock:
            return [
                e for n, e, trusted in self._event_log
                if trusted and n > since and e.object == robot and e.user == self.user and e.kind in REJECT_KINDS
            ]

    def recent_events(self, limit: int = 20) -> list[tuple[Event, bool]]:
        """The latest ``limit`` events, oldest first, each with whether it came from its object's authority
        (False: display-only, e.g. a decode report any login may write; the TUI marks those)."""
        with self._events_lock:
            return [(e, trusted) for _, e, trusted in self._event_log[-limit:]]
