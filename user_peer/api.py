"""The Python API for users: a world, its robots and scene objects, as plain objects and blocking calls.

The replacement for the paper's MATLAB scripts::

    import user_peer
    with user_peer.connect(world="demo", user="alice") as world:
        arm = world.robot("arm1")
        arm.request()
        arm.move_to([3.15, 0.0, 1.0])      # IK by a compute peer, then the joints
        print(arm.joints)

A :class:`World` is one user peer: one Zenoh session with a liveliness token
``rf/{world}/peer/user/{user}`` (ownership leases rely on it), replicas of the
latest joints, pose, scan, path and ownership record of every robot it has
been asked about, and the services of compute peers. Blocking calls wait on
those replicas with deadlines and raise :class:`NotOwner`, :class:`Unreachable`
or :class:`Timeout` with a reason; nothing blocks forever. Works the same in a
script and in Jupyter (no event loop of its own: Zenoh's threads feed it).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import OrderedDict
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from fabric import keys
from fabric.config import FabricConfig
from fabric.fencing import is_authority_event
from fabric.interfaces import (
    REJECT_KINDS,
    Command,
    Event,
    JointState,
    JointTarget,
    OccupancyGrid,
    OwnershipRecord,
    Path,
    Pose,
    Reset,
    Scan,
    Stop,
    Twist,
    WorldInfo,
    quaternion_from_yaw,
    yaw_from_quaternion,
)
from fabric.reliable import resend_until
from fabric.interfaces import ServiceError
from fabric.session import Fabric
from user_peer import services
from fabric.exit import at_exit
from user_peer.errors import JoinFailed, NotOwner, Timeout, Unreachable
from user_peer.ownership_link import OwnershipLink
from user_peer.spread import SPREAD, RoundRobin
from user_peer.streams import StreamIterator, Subscription

log = logging.getLogger("robofabric.user")

__all__ = ["connect", "World", "Robot", "Arm", "Base", "SceneObject"]


FOLLOWED_STREAMS = ("joints", "pose", "scan", "path", "ik")
"""The streams a robot handle keeps the latest of (:meth:`World.robot`)."""

FIRST_STATE_WAIT_S = 1.0
"""How long a new robot handle waits for the robot's first state (a live sim sends it within a stream period)."""

COMMAND_ROUTE_WAIT_S = 0.5
"""How long a command waits for its sim's subscription to be known before it is put anyway."""


class _Latest:
    """The latest message per key, with a condition to wait for a newer one.

    Freshness is judged on this machine only: every message gets a local arrival number (``mark()``
    reads the current one) and a local receive time from ``clock`` (monotonic ns). A header's
    ``wall_ns`` comes from another machine's clock and is never compared with ours (issue 15).

    Bounded by what the world has, not by what clients make up (issue 14): once ``world_info()``
    gives the world description, a robot key (``robot/{id}/...``) or record (``own/{id}``) is kept only
    for a robot or object of that description; anything else (before the description, maps, events)
    shares ``max_other`` places, the least recently updated forgotten first. A made-up
    ``robot/fakeN/scan`` of 4 MiB each no longer grows a user's memory without bound.
    """

    def __init__(self, clock: Callable[[], int] = time.monotonic_ns, *, world_info: Callable[[], WorldInfo | None] | None = None,
                 max_other: int = 64) -> None:
        self._values: dict[str, tuple[Any, int, int]] = {}
        self._other: OrderedDict[str, None] = OrderedDict()  # keys outside the description, oldest update first
        self._cond = threading.Condition()
        self._gen = 0
        self._clock = clock
        self._world_info = world_info
        self._max_other = max_other
        self._ids: tuple[Any, frozenset[str]] = (None, frozenset())  # (description, its robot and object ids)
        self.dropped = 0  # messages on keys of robots the world does not have

    def _known(self, key: str) -> bool | None:
        """True: a key of the world's robots or objects; False: of one it does not have; None: no description
        yet, or a key of another kind."""
        info = self._world_info() if self._world_info is not None else None
        if info is None:
            return None
        if self._ids[0] is not info:
            self._ids = (info, frozenset(r.id for r in info.robots) | frozenset(o.id for o in info.objects))
        parts = key.split("/", 4)  # rf/{world}/{category}/{subject}/...: the object pose key here ends in a wildcard
        if len(parts) >= 4 and parts[2] in ("robot", "own", "object"):
            return parts[3] in self._ids[1]
        return None

    def put(self, key: str, msg: Any) -> None:
        known = self._known(key)
        if known is False:
            self.dropped += 1
            return
        with self._cond:
            self._gen += 1
            if known:
                self._other.pop(key, None)
            elif key in self._other:
                self._other.move_to_end(key)
            else:
                self._other[key] = None
                while len(self._other) > self._max_other:
                    self._values.pop(self._other.popitem(last=False)[0], None)
            self._values[key] = (msg, self._gen, self._clock())
            self._cond.notify_all()

    def get(self, key: str) -> Any:
        with self._cond:
            v = self._values.get(key)
            return v[0] if v else None

    def mark(self) -> int:
        """The arrival number of the newest message so far: ``get_after(key, mark)`` ignores older ones."""
        with self._cond:
            return self._gen

    def get_after(self, key: str, mark: int) -> Any:
        """The latest message on ``key`` if it arrived after ``mark``, else None."""
        with self._cond:
            v = self._values.get(key)
            return v[0] if v and v[1] > mark else None

    def age(self, key: str) -> float | None:
        """Seconds since the latest message on ``key`` arrived here (None: nothing yet)."""
        with self._cond:
            v = self._values.get(key)
        return None if v is None else max(0.0, (self._clock() - v[2]) * 1e-9)

    def wait_for(self, predicate: Callable[[], Any], timeout: float) -> Any:
        """Re-evaluate ``predicate`` on every new message until it is truthy or ``timeout`` passes."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                value = predicate()
                if value:
                    return value
                left = deadline - time.monotonic()
                if left <= 0:
                    return value
                self._cond.wait(min(left, 0.1))


def _fmt_age(age: float | None) -> str:
    if age is None:
        return "no data yet"
    return f"{age * 1e3:.0f} ms ago" if age < 1.0 else f"{age:.1f} s ago"


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
        self.latest = _Latest(world_info=lambda: self._info)  # keeps the robots of the description only
        self.events: list[Event] = []
        # (local arrival number, event, trusted): trusted when a sim-only key carried it from the object's
        # authority (_from_authority); only those can refuse a command here, the rest is display-only
        self._event_log: list[tuple[int, Event, bool]] = []
        self.untrusted_events = 0  # events acted on by nothing: any login may write their keys, or not the authority's
        self._events_seen = 0
        self._events_lock = threading.Lock()
        self._closed = False
        self._robots: dict[str, Robot] = {}
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
        self._world_callbacks: list[Callable[[bool, str], None]] = []
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
        if self._closed:
            return f"<World {self.name!r} as {self.user!r}, closed>"
        if self._info is not None:  # every robot of the world, not only those asked for so far
            for entry in services.robot_entries(self._info):
                self.robot(entry.id)
        robots = "; ".join(r.status() for r in self._robots.values())
        known = "" if self._info is not None else ", world not seen yet"
        return f"<World {self.name!r} as {self.user!r}{known}" + (f": {robots}>" if robots else ">")

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
        while True:
            left = deadline - time.monotonic()
            try:
                self._info = services.world_info(self.fabric, timeout=max(0.05, min(left, 2.0)))
                return True
            except ServiceError:
                if left <= 0:
                    return False
                time.sleep(min(0.1, max(0.0, left)))

    def _on_sim(self, kind: str, peer_id: str, alive: bool) -> None:
        with self._world_cond:
            was = bool(self._sims)
            (self._sims.add if alive else self._sims.discard)(peer_id)
            now = bool(self._sims)
            callbacks = list(self._world_callbacks) if now != was else []
            self._world_cond.notify_all()
        if now == was:
            return
        why = f"sim peer {peer_id} is back" if now else f"world {self.name!r} gone: its sim peer {peer_id} left (died, or cut off)"
        if now:
            self._info = None  # a restarted sim may describe a different world: ask again
            log.info("world %s is back: sim peer %s", self.name, peer_id)
        else:
            log.warning("%s", why)
        for cb in callbacks:
            try:
                cb(now, why)
            except Exception:
                log.exception("world callback failed")

    # ------------------------------------------------------------------ what is there

    def info(self, *, refresh: bool = False, timeout: float | None = None) -> WorldInfo:
        """The sim peer's world description (robots, types, limits, sensors).

        The first call waits up to ``timeout`` (default ``join_timeout``) for a sim peer to serve it, so a
        script may start before the sim; :class:`Timeout` says how long it waited and what it saw.
        """
        if self._info is None or refresh:
            wait = self.join_timeout if timeout is None else timeout
            self._info = self._wait_world(wait)
        return self._info

    def _wait_world(self, wait: float) -> WorldInfo:
        key = keys.srv(self.name, "world")
        t0 = time.monotonic()
        deadline = t0 + wait
        last = ""
        while True:
            left = deadline - time.monotonic()
            try:
                # at most a few seconds per try: a query sent before any sim existed is never answered later
                return services.world_info(self.fabric, timeout=max(0.05, min(left, 2.0)))
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

    def robot(self, robot_id: str) -> "Robot":
        """An :class:`Arm` or a :class:`Base`, by the robot's kind in the world description."""
        if robot_id not in self._robots:
            entry = next((r for r in services.robot_entries(self.info()) if r.id == robot_id), None)
            if entry is None:
                raise Unreachable(f"no robot {robot_id!r} in world {self.name!r}; robots: {', '.join(self.robots()) or 'none'}")
            cls = Arm if entry.kind == "arm" else Base
            self._robots[robot_id] = cls(self, entry)
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

    def object(self, object_id: str) -> "SceneObject":
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
        return key_expr if key_expr.startswith(keys.PREFIX + "/") else f"{keys.world_root(self.name)}/{key_expr}"

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
        :meth:`event_mark`). Judged by arrival here, never by the sender's clock (issue 15). Only the robot's
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


def _still_after(msg: Any, seq: int) -> bool:
    """Whether ``msg`` (a robot's JointState or Pose) came after sequence number ``seq`` and shows it still."""
    if msg is None or msg.header.seq <= seq:
        return False
    if isinstance(msg, JointState):
        return float(np.max(np.abs(msg.dq), initial=0.0)) < 1e-6
    return float(np.linalg.norm(msg.linear)) < 1e-3 and float(np.linalg.norm(msg.angular)) < 1e-3


class Robot:
    """What every robot offers: ownership, stop, reset, its streams."""

    kind = ""

    def __init__(self, world: World, entry: services.RobotEntry) -> None:
        self.world = world
        self.id = entry.id
        self.type = entry.type
        self.entry = entry
        self._w = world.name
        if world.keep_latest(self.id):  # a new handle: its first state, briefly (the latest was not kept before)
            key = keys.robot_stream(self._w, self.id, self._data_stream)
            world.latest.wait_for(lambda: world.latest.get(key), min(world.timeout, FIRST_STATE_WAIT_S))

    _data_stream = "joints"  # the stream whose age repr reports

    def status(self) -> str:
        """One line: id, owner (you / someone / nobody), motion state, age of the latest data here."""
        rec = self.record
        if rec is None:
            who = "no ownership record"
        elif rec.owner == self.world.user:
            who = "owned by you"
        elif rec.owner:
            who = f"owned by {rec.owner}"
        else:
            who = "free"
        if rec is not None and rec.queue:
            who += f", queue: {', '.join(rec.queue)}"
        state = f", {rec.state}" if rec is not None else ""
        age = self.world.latest.age(keys.robot_stream(self._w, self.id, self._data_stream))
        return f"{self.id} ({self.type}): {who}{state}, {self._data_stream} {_fmt_age(age)}"

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.status()}>"

    # ------------------------------------------------------------------ ownership

    @property
    def record(self) -> OwnershipRecord | None:
        return self.world.ownership.record(self.id)

    @property
    def owner(self) -> str:
        rec = self.record
        return rec.owner if rec else ""

    @property
    def is_owner(self) -> bool:
        return self.owner == self.world.user

    @property
    def can_command(self) -> bool:
        """True when this user owns the robot, or the world runs without ownership (no record at all)."""
        rec = self.record
        return rec is None or rec.owner == self.world.user

    def request(self, *, timeout: float | None = None, wait: bool = False) -> int:
        """Ask to own the robot; returns the epoch (the fencing token the commands carry).

        Without ``wait`` a refusal raises :class:`NotOwner` with the authority's reason (in motion, owned
        by X). With ``wait`` the user takes a place in the queue and this call returns the epoch when that
        place becomes ownership, or raises :class:`Timeout` after ``timeout`` s, leaving the queue.
        """
        return self.world.ownership.request(self.id, timeout=timeout or self.world.timeout, wait=wait)

    def release(self) -> None:
        self.world.ownership.release(self.id, timeout=self.world.timeout)

    # ------------------------------------------------------------------ commands

    def send(self, command: str, body: Any) -> None:
        """Send a command under this user's current epoch; :class:`NotOwner` if we know we do not own it.

        With no ownership record at all (a world run without ownership) the command goes out with
        epoch 0 and the sim, the authority, decides.
        """
        rec = self.record
        if rec is None:  # no replica yet (joined before the authority published): ask it, briefly
            rec = self.world.ownership.fetch(self.id, timeout=min(self.world.timeout, 1.0))
        if rec is not None and rec.owner != self.world.user:
            who = rec.owner or "nobody"
            raise NotOwner(f"{self.world.user} does not own {self.id} (owner: {who}); call request() first")
        key = keys.robot_cmd(self._w, self.id, command, self.world.user)
        epoch = rec.epoch if rec is not None else 0
        # a sim that has just (re)started may not be known as a listener yet: its first command was lost
        # (the lab's clock-skew scenario, sim restarted: the sim counted 0 commands, the move timed out)
        self.world.fabric.wait_matching(key, COMMAND_ROUTE_WAIT_S)
        self.world.fabric.publish(key, Command(self.world.user, epoch, body, self.world.fabric.header(key)))

    def stop(self, *, confirm: bool = True, timeout: float = 3.0) -> bool:
        """Stop the robot where it is. Commands are dropped, not queued, when the network is congested, so
        with ``confirm`` the stop is sent again every 0.1 s until the robot's own stream shows it still
        (:func:`fabric.reliable.resend_until`); returns whether it was seen still within ``timeout``."""
        return self._control("stop", Stop, confirm, timeout)

    def reset(self, *, confirm: bool = True, timeout: float = 10.0) -> bool:
        """Send the robot back to its start (an arm at its speed limits); with ``confirm``, sent again until
        the robot is seen still (an arm: still at its start), as :meth:`stop`. Returns whether it was within ``timeout``."""
        return self._control("reset", Reset, confirm, timeout)

    def _control(self, command: str, body_type: type, confirm: bool, timeout: float) -> bool:
        key = keys.robot_cmd(self._w, self.id, command, self.world.user)
        stream = "joints" if self.kind == "arm" else "pose"
        before = self.latest(stream)
        seq0 = -1 if before is None else before.header.seq

        def send() -> None:
            self.send(command, body_type(self.world.fabric.header(key)))

        if not confirm:
            send()
            return False
        at = self._reset_target() if command == "reset" else None

        def done() -> bool:
            msg = self.latest(stream)
            if not _still_after(msg, seq0):
                return False
            # a still arm right after the send may not have begun its reset yet: it must be still *there*
            return at is None or float(np.max(np.abs(np.asarray(msg.q) - at), initial=0.0)) < 1e-3

        return resend_until(send, done, interval=0.1, timeout=timeout).done

    def _reset_target(self) -> np.ndarray | None:
        """Where an arm's reset takes its joints (zero, within range, as the sim's controller does); None
        for a base (teleported home, still at once) or an arm whose limits the world did not give."""
        e = self.entry
        if self.kind != "arm" or not e.lower or len(e.lower) != len(e.upper):
            return None
        return np.clip(np.zeros(len(e.lower)), np.asarray(e.lower), np.asarray(e.upper))

    def _check_rejected(self, since: int) -> None:
        rej = self.world.rejections(self.id, since)
        if rej:
            raise NotOwner(f"{self.id} refused the command: {rej[-1].reason}")

    # ------------------------------------------------------------------ streams

    def latest(self, stream: str) -> Any:
        return self.world.latest.get(keys.robot_stream(self._w, self.id, stream))

    def age(self, stream: str) -> float | None:
        """Seconds since this robot's latest ``stream`` message arrived here (None: none yet). Measured
        on this machine's clock only, so a sim whose clock is off ours does not skew it."""
        return self.world.latest.age(keys.robot_stream(self._w, self.id, stream))

    def on(self, stream: str, callback: Callable[[str, Any], None]) -> Subscription:
        """``callback(key, message)`` on each message of one of this robot's streams (joints, pose, scan, path)."""
        return self.world.on(keys.robot_stream(self._w, self.id, stream), callback)

    def stream(self, stream: str, **kw: Any) -> StreamIterator:
        return self.world.stream(keys.robot_stream(self._w, self.id, stream), **kw)

    def wait_for(self, stream: str, *, timeout: float | None = None) -> Any:
        """The latest message of a stream, waiting for a first one if none has arrived yet."""
        key = keys.robot_stream(self._w, self.id, stream)
        msg = self.world.latest.wait_for(lambda: self.world.latest.get(key), timeout or self.world.timeout)
        if msg is None:
            raise Timeout(f"no {stream} from {self.id} within {timeout or self.world.timeout:.1f} s (is the sim running?)")
        return msg


class Arm(Robot):
    """A robot arm: joint moves and Cartesian moves through a compute peer's IK."""

    kind = "arm"

    @property
    def joint_state(self) -> JointState | None:
        return self.latest("joints")

    @property
    def joints(self) -> np.ndarray | None:
        """The latest joint positions (rad), or None before the first JointState."""
        js = self.joint_state
        return None if js is None else np.array(js.q)

    @property
    def flange(self) -> Pose | None:
        return self.latest("pose")

    def move_joints(
        self, q: Sequence[float], *, wait: bool = True, tol: float = 1e-3, timeout: float = 20.0, speed_scale: float = 1.0
    ) -> np.ndarray:
        """Command joint targets (rad). With ``wait``, block until within ``tol`` of them and still."""
        target = np.asarray(q, dtype=float)
        n = len(self.entry.joint_names)
        if target.shape != (n,):
            raise ValueError(f"{self.id} has {n} joints, got {target.shape[0] if target.ndim else 0} values")
        if not np.isfinite(target).all():
            raise ValueError(f"joint targets must be finite, got {target.tolist()}")
        lo, hi = np.asarray(self.entry.lower), np.asarray(self.entry.upper)
        if lo.shape == target.shape and ((target < lo - 1e-9) | (target > hi + 1e-9)).any():
            j = int(np.flatnonzero((target < lo - 1e-9) | (target > hi + 1e-9))[0])
            raise Unreachable(
                f"{self.entry.joint_names[j]} target {math.degrees(target[j]):.1f} deg is outside its limits "
                f"[{math.degrees(lo[j]):.1f}, {math.degrees(hi[j]):.1f}] deg"
            )
        marks = self.world.event_mark(), self.world.latest.mark()
        key = keys.robot_cmd(self._w, self.id, "joints", self.world.user)
        self.send("joints", JointTarget(target, speed_scale, self.world.fabric.header(key)))
        if not wait:
            return target
        return self._wait_joints(target, tol, timeout, marks)

    def _wait_joints(self, target: np.ndarray, tol: float, timeout: float, marks: tuple[int, int]) -> np.ndarray:
        """Until joints that arrived after the command (local arrival order, never the sim's clock) are at
        ``target`` and still; a rejection that arrived after it raises :class:`NotOwner`."""
        key = keys.robot_joints(self._w, self.id)
        events_mark, data_mark = marks

        def done() -> bool:
            self._check_rejected(events_mark)
            js = self.world.latest.get_after(key, data_mark)
            if js is None:
                return False
            return bool(np.max(np.abs(np.asarray(js.q) - target)) <= tol and np.max(np.abs(js.dq)) < 1e-2)

        if not self.world.latest.wait_for(done, timeout):
            js = self.world.latest.get(key)
            err = float(np.max(np.abs(np.asarray(js.q) - target))) if js is not None else float("nan")
            raise Timeout(f"{self.id} did not reach its joint targets within {timeout:.1f} s (max error {math.degrees(err):.2f} deg)")
        return np.array(self.world.latest.get(key).q)

    def ik(self, xyz: Sequence[float], quaternion: Sequence[float] | None = None) -> np.ndarray:
        """Joint angles placing the flange at ``xyz`` (world frame, m), from a compute peer.

        :class:`Unreachable` when the compute peer refuses (with its reason), :class:`Timeout` when none answers.
        """
        try:
            return self.world.ask_kinematics(
                lambda peer: services.ik(self.world.fabric, self.id, xyz, quaternion, self.joints, timeout=self.world.timeout, peer=peer)
            )
        except ServiceError as exc:
            if exc.reason.startswith("no reply"):
                raise Timeout(f"IK for {self.id}: {exc.reason}") from None
            raise Unreachable(f"IK for {self.id} at {list(map(float, xyz))}: {exc.reason}") from None

    @property
    def ik_stream(self) -> Any:
        """The latest streamed IK solution (``fabric.interfaces.IKStream``) for this arm, or None."""
        return self.latest("ik")

    def wait_ik_stream(self, xyz: Sequence[float], *, timeout: float | None = None, tol: float = 1e-9) -> Any:
        """The streamed IK solution for a target at ``xyz`` (world frame), once a compute peer has solved it.

        Streaming runs in a compute peer started with ``--stream ROBOT:OBJECT``; :class:`Timeout` if no
        solution for this target arrives in time. Check ``.ok`` / ``.reason`` before applying ``.q``.
        """
        goal = np.asarray(xyz, dtype=float)
        key = keys.robot_stream(self._w, self.id, "ik")

        def match() -> Any:
            msg = self.world.latest.get(key)
            if msg is not None and np.max(np.abs(np.asarray(msg.position) - goal)) <= tol:
                return msg
            return None

        wait = self.world.timeout if timeout is None else timeout
        msg = self.world.latest.wait_for(match, wait)
        if msg is None:
            raise Timeout(f"no streamed IK for {self.id} at {goal.tolist()} within {wait:.1f} s (is a compute peer streaming it?)")
        return msg

    def move_to(
        self, xyz: Sequence[float], quaternion: Sequence[float] | None = None, *, wait: bool = True, tol: float = 1e-3, timeout: float = 20.0
    ) -> np.ndarray:
        """Move the flange to ``xyz`` (world frame, m) through IK; :class:`Unreachable` if IK refuses.

        ``tol`` is on the joints (rad), as in :meth:`move_joints`; returns the joints reached.
        """
        q = self.ik(xyz, quaternion)
        return self.move_joints(q, wait=wait, tol=tol, timeout=timeout)


class Base(Robot):
    """A mobile base: twist driving, mapping, planning and path following."""

    kind = "mobile"
    _data_stream = "pose"

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

    def twist(self, v: float, omega: float) -> None:
        """One twist command (m/s, rad/s); the sim keeps it until the next one or a stop."""
        key = keys.robot_cmd(self._w, self.id, "twist", self.world.user)
        self.send("twist", Twist(float(v), float(omega), self.world.fabric.header(key)))

    def drive(self, v: float, omega: float, duration: float, *, rate: float = 10.0) -> tuple[float, float, float] | None:
        """Drive at (v, omega) for ``duration`` seconds (repeating the twist at ``rate`` Hz), then stop."""
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
            services.map_request(self.world.fabric, "start", name=name, timeout=self.world.timeout, peer=self.world.navigation_peer(),
                                 user=self.world.user)
        except ServiceError as exc:
            raise Unreachable(f"mapping for {self.id}: {exc.reason}") from None

    def build_map(self, *, name: str = "map", threshold: float = 0.65, timeout: float | None = None) -> OccupancyGrid:
        """The binary map a compute peer built from the scans so far (also published on ``map/{name}``)."""
        try:
            return services.build_map(
                self.world.fabric, name=name, threshold=threshold, timeout=timeout or max(self.world.timeout, 10.0), peer=self.world.navigation_peer(),
                user=self.world.user,
            )
        except ServiceError as exc:
            raise Unreachable(f"map for {self.id}: {exc.reason}") from None

    def plan_to(
        self, x: float | None = None, y: float | None = None, theta: float = 0.0, *, planner: str = "hybrid_astar",
        map_name: str = "map", timeout: float | None = None,
    ) -> Path:
        """A collision-free path from the robot's pose to (x, y, theta), or to the goal object without x, y."""
        goal = None if x is None or y is None else (float(x), float(y), float(theta))
        try:
            return services.plan(
                self.world.fabric, self.id, goal, planner=planner, map_name=map_name, timeout=timeout or max(self.world.timeout, 15.0),
                peer=self.world.navigation_peer(), user=self.world.user,
            )
        except ServiceError as exc:
            where = "the goal object" if goal is None else f"({goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.2f})"
            raise Unreachable(f"no path for {self.id} to {where}: {exc.reason}") from None

    def follow(self, path: Path, *, wait: bool = True, tol: float = 0.25, timeout: float = 120.0) -> tuple[float, float, float] | None:
        """Send ``path`` to the sim's follower; with ``wait``, block until the base stops near its end."""
        if len(path) == 0:
            raise ValueError("cannot follow an empty path")
        events_mark, data_mark = self.world.event_mark(), self.world.latest.mark()
        key = keys.robot_cmd(self._w, self.id, "path", self.world.user)
        body = Path(path.x, path.y, path.theta, path.frame, self.world.fabric.header(key))
        self.send("path", body)
        if not wait:
            return self.xy_theta
        gx, gy = float(path.x[-1]), float(path.y[-1])
        pkey = keys.robot_pose(self._w, self.id)

        def arrived() -> bool:
            self._check_rejected(events_mark)
            p = self.world.latest.get_after(pkey, data_mark)  # a pose that arrived after the command
            if p is None:
                return False
            near = math.hypot(p.position[0] - gx, p.position[1] - gy) <= tol
            still = math.hypot(p.linear[0], p.linear[1]) < 0.02 and abs(p.angular[2]) < 0.05
            return near and still

        if not self.world.latest.wait_for(arrived, timeout):
            xy = self.xy_theta
            where = f"({xy[0]:.2f}, {xy[1]:.2f})" if xy else "unknown"
            raise Timeout(f"{self.id} did not reach the end of its path ({gx:.2f}, {gy:.2f}) within {timeout:.0f} s; it is at {where}")
        return self.xy_theta


class SceneObject:
    """A scene object (policy ``scene``: anyone writes, last writer wins)."""

    def __init__(self, world: World, object_id: str) -> None:
        self.world = world
        self.id = object_id
        self.key = keys.object_pose(world.name, object_id, world.user)  # where this user writes it
        self.any_key = keys.object_pose_all(world.name, object_id)  # where anyone's pose of it is read

    def __repr__(self) -> str:
        return f"<SceneObject {self.id!r}>"

    @property
    def pose(self) -> Pose | None:
        return self.world.latest.get(self.any_key)

    def set_pose(self, position: Sequence[float], quaternion: Sequence[float] = (1.0, 0.0, 0.0, 0.0), *, yaw: float | None = None) -> Pose:
        """Move the object to ``position`` (m, world frame); ``yaw`` (rad) overrides ``quaternion``."""
        if yaw is not None:
            quaternion = quaternion_from_yaw(yaw)
        pose = Pose(np.asarray(position, dtype=float), np.asarray(quaternion, dtype=float), header=self.world.fabric.header(self.key))
        self.world.fabric.publish(self.key, pose)
        self.world.latest.put(self.any_key, pose)
        return pose

    def on(self, callback: Callable[[str, Any], None]) -> Subscription:
        return self.world.on(self.any_key, callback)


def connect(
    world: str | None = None,
    connect: Iterable[str] | str | None = None,
    user: str | None = None,
    *,
    profile: str | None = None,
    zenoh_config: str | None = None,
    timeout: float = 5.0,
    compute: str | None = None,
    wait: bool = True,
    join_timeout: float | None = None,
) -> World:
    """Join a world as ``user`` (default: $USER). ``connect``: router endpoints, e.g. ``["tcp/10.0.0.5:7447"]``
    (default ``$ROBOFABRIC_CONNECT``); ``world`` defaults to ``$ROBOFABRIC_WORLD`` or ``demo``.

    With ``wait`` (the default) it returns once a sim peer serves the world's description, waiting up
    to ``join_timeout`` seconds (default 30, at least ``timeout``) for one to start; :class:`Timeout`
    otherwise, saying how long it waited. ``timeout`` is the default for service calls afterwards.

    ``compute``: the peer id of the compute peer to use (``robofabric ps`` lists them), e.g. one running on
    this machine; ``"spread"`` sends IK queries to every live compute peer in turn; by default queries go
    to the nearest compute peer serving the world.

    A world that cannot be joined raises :class:`~user_peer.errors.JoinFailed` (an ``Unreachable``) with
    ``endpoint`` and ``cause``: nobody listens there, the router refused this login, or this client refused
    the router's TLS certificate (one that does not name the host asked for, or from another class's CA).

    The world closes itself when the interpreter exits (its robots are released first), so a script
    may end without ``close()``; ``with user_peer.connect(...) as world:`` closes it sooner.
    """
    import getpass

    if isinstance(connect, str):
        connect = [connect]
    cfg = FabricConfig.resolve(world=world, profile=profile, connect=list(connect or ()), config_file=zenoh_config)
    # with a secure zenoh config the user id is the login (a different ``user`` is a ConfigError)
    uid = cfg.user_id(user) or "".join(c if c.isalnum() or c in "-_" else "-" for c in getpass.getuser()) or "user"
    try:
        w = World(cfg, uid, timeout=timeout, compute=compute, join_timeout=join_timeout)
    except JoinFailed as exc:  # raised here: a script's traceback ends at its own connect() call
        raise JoinFailed(exc.reason, endpoint=exc.endpoint, cause=exc.cause) from None
    if wait:
        try:
            w.info()
        except BaseException:
            w.close()
            raise
    return w
