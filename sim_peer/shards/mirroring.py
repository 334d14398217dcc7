"""Feeding mirrors: the other sims' robots, from their pose and joint streams, into this sim's world.

A sim that shares its world with other sims (docs/sim.md, "Several sims, one world") follows every
``robot/*/pose`` another session publishes. A robot that is not this world's own is looked up in the
world's ``srv/world`` union and gets a mirror (:mod:`sim_peer.physics.mirrors`):

- a mobile base: one cylinder sized from its ``BaseInfo``, placed at each pose as it arrives;
- an arm: its link geoms (:mod:`sim_peer.physics.arm_mirror`), placed from its ``joints`` stream (its ``pose`` is
  its flange, which says nothing of its links), followed once the description names it an arm, at most
  every ``ARM_PERIOD_S``.

Mirrors move under the peer's lock, between two steps. A mirror is hidden when its sim's token goes, or
when nothing came for ``stale_s`` (its sim paused or was cut off: an obstacle frozen where it was last seen
would be a lie the LIDAR keeps telling).

How late a mirror is, is measured here: a message's age on arrival, by the sender's wall clock (meaningful
on one machine or with synchronised clocks), plus the stream's period (``bench shards`` reports both).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from typing import Any, Callable

from fabric import keys
from fabric.interfaces import JointState, Pose, RobotInfo, ServiceError, WorldInfo
from robots.kinds import facts
from sim_peer.physics.arm_mirror import ArmShape, arm_shape
from sim_peer.physics.world import SimWorld

log = logging.getLogger("robofabric.sim")

__all__ = ["ARM_PERIOD_S", "MirrorFeed", "STALE_S"]

STALE_S = 2.0
"""A mirror with no pose for this long is hidden (a transport lease: its sim is paused or cut off)."""

DESCRIBE_EVERY_S = 1.0
"""How often an unknown robot's pose may make the feed ask the world's description again."""

ARM_PERIOD_S = 0.02
"""An arm's mirror moves at most this often (its joints come at 100 Hz; sensors read at 20-50 Hz)."""

MAX_ARMS = 256  # arms followed (each a subscription): bounded, whatever a world description says
MAX_UNSLOTTED = 256  # robots told of as finding no slot (once each; bounded)
MAX_LAGS = 4096
MAX_DEPARTED = 256  # sims remembered as gone (bounded: anyone may declare a token)


class MirrorFeed:
    """The other sims' robots as mirrors in ``world``; a context manager, ``close()`` idempotent.

    ``describe()`` answers the world's description (the union of every sim's part); ``lock`` is the lock the
    sim steps its world under; ``clock`` is monotonic seconds (tests pass their own)."""

    def __init__(
        self,
        fab: Any,
        world: SimWorld,
        lock: threading.RLock,
        *,
        describe: Callable[[], WorldInfo] | None = None,
        stale_s: float = STALE_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fab, self.world, self.lock = fab, world, lock
        self.stale_s = stale_s
        self._clock = clock
        self._describe = describe or self._ask_world
        self._bases: dict[str, RobotInfo] = {}  # other sims' mobile robots, from the description
        self._arms: dict[str, RobotInfo] = {}  # other sims' arms, from the description
        self._shapes: dict[str, ArmShape] = {}  # arms followed: their link geoms
        self._arm_subs: dict[str, Any] = {}  # arm -> its joints subscription
        self._moved_at: dict[str, float] = {}  # arm -> when its mirror last moved
        self._unslotted: set[str] = set()  # robots that found too few free slots (said once each)
        self._seen: dict[str, float] = {}  # robot -> when its last pose arrived here
        self._asked_at = float("-inf")
        self._asking = False
        self._departed: set[str] = (
            set()
        )  # sims whose token went: their poses still in flight must not show a mirror again
        self._state = threading.Lock()
        self.lag_ms: deque[float] = deque(maxlen=MAX_LAGS)  # a pose's age on arrival, by the sender's clock
        self.counters = {
            "poses": 0,
            "joints": 0,
            "unknown": 0,
            "shown": 0,
            "hidden": 0,
            "unmirrorable": 0,
            "unslotted": 0,
        }
        self._closed = False
        self._stop = threading.Event()
        self._subs = [
            fab.subscribe(keys.robot_stream_all(fab.world, "pose"), self._on_pose, expected=Pose, remote_only=True),
            fab.watch_peers(self._on_sim, kind="sim"),
        ]
        self._sweeper = threading.Thread(target=self._sweep_loop, name="mirror-sweep", daemon=True)
        self._sweeper.start()

    # ------------------------------------------------------------------ what the others publish

    def _ask_world(self) -> WorldInfo:
        from fabric.worldview import describe

        return describe(self.fab, timeout=2.0)

    def _learn(self) -> None:
        """Ask the world's description again (in its own thread: never in a subscriber callback)."""
        try:
            info = self._describe()
        except (ServiceError, ValueError) as exc:
            log.debug("mirrors: no world description yet: %s", exc)
            info = None
        follow: dict[str, ArmShape] = {}
        if info is not None:
            for r in info.robots:
                if (
                    not facts(r.kind).chain
                    or r.id in self.world.robots
                    or r.id in self._shapes
                    or len(self._shapes) + len(follow) >= MAX_ARMS
                ):
                    continue
                try:
                    follow[r.id] = arm_shape(r)
                except ValueError as exc:  # a type this machine does not have: seen by no sensor here
                    self.counters["unmirrorable"] += 1
                    log.warning("cannot mirror %s: %s", r.id, exc)
        with self._state:
            self._asking = False
            if info is not None:
                self._bases = {r.id: r for r in info.robots if r.base is not None and r.id not in self.world.robots}
                self._arms = {r.id: r for r in info.robots if facts(r.kind).chain and r.id not in self.world.robots}
            if self._closed:
                return
            self._shapes.update(follow)
        for rid in follow:  # declared here, in this thread: never from a subscriber callback
            sub = self.fab.subscribe(
                keys.robot_joints(self.fab.world, rid), self._on_joints, expected=JointState, remote_only=True
            )
            with self._state:
                closed = self._closed
                if not closed:
                    self._arm_subs[rid] = sub
            if closed:
                sub.undeclare()

    def _footprint(self, robot: str) -> RobotInfo | None:
        with self._state:
            info = self._bases.get(robot)
            if info is not None:
                return info
            now = self._clock()
            if self._asking or now - self._asked_at < DESCRIBE_EVERY_S:
                return None
            self._asking, self._asked_at = True, now
        threading.Thread(target=self._learn, name="mirror-describe", daemon=True).start()
        return None

    def _on_pose(self, key: str, pose: Pose) -> None:
        robot = keys.parse(key).subject
        if robot in self.world.robots or self._closed or robot in self._arms:
            return  # an arm's pose is its flange: its mirror follows its joints
        self.counters["poses"] += 1
        info = self._footprint(robot)
        if info is None:
            self.counters["unknown"] += 1
            return
        if pose.header.wall_ns:
            self.lag_ms.append(max(0.0, (time.time_ns() - pose.header.wall_ns) / 1e6))
        with self.lock:  # (lock, then state: as _on_sim, so a departure and a late pose never interleave)
            with self._state:
                if pose.header.source in self._departed:  # sent just before its sim left, arriving just after
                    return
            was = self.world.mirrors.holds(robot)
            shown = self.world.mirror(
                robot,
                radius=info.base.radius,
                height=info.base.height or 0.3,
                position=pose.position,
                quaternion=pose.quaternion,
                source=pose.header.source or info.sim,
            )
        if shown:
            with self._state:
                self._seen[robot] = self._clock()
            if not was:
                self.counters["shown"] += 1
                log.info("mirroring %s (simulated by %s)", robot, pose.header.source or info.sim)
        elif not was:
            self._no_slot(robot, 1, pose.header.source or info.sim)

    def _on_joints(self, key: str, js: JointState) -> None:
        robot = keys.parse(key).subject
        shape = self._shapes.get(robot)
        if shape is None or robot in self.world.robots or self._closed:
            return
        self.counters["joints"] += 1
        now = self._clock()
        if now - self._moved_at.get(robot, float("-inf")) < ARM_PERIOD_S:
            return
        if js.header.wall_ns:
            self.lag_ms.append(max(0.0, (time.time_ns() - js.header.wall_ns) / 1e6))
        info = self._arms.get(robot)
        source = js.header.source or (info.sim if info is not None else "")
        with self.lock:
            with self._state:
                if source in self._departed:
                    return
            poses = shape.poses(js.q)
            if poses is None:
                return
            was = self.world.mirrors.holds(robot)
            shown = self.world.mirror_shapes(robot, shape.shapes, poses, source=source)
        if shown:
            with self._state:
                self._seen[robot] = now
                self._moved_at[robot] = now
            if not was:
                self.counters["shown"] += 1
                log.info("mirroring %s (simulated by %s; %d link geoms)", robot, source, len(shape.shapes))
        elif not was:
            self._no_slot(robot, len(shape.shapes), source)

    def _no_slot(self, robot: str, needed: int, source: str) -> None:
        """Say once per robot that the pool is too small for it (a bad pose, with slots free, says nothing):
        a LIDAR that does not see another sim's robot is otherwise a mystery."""
        mirrors = self.world.mirrors
        if mirrors.free >= needed:
            return
        with self._state:
            if robot in self._unslotted or len(self._unslotted) >= MAX_UNSLOTTED:
                return
            self._unslotted.add(robot)
        self.counters["unslotted"] += 1
        log.warning(
            "cannot mirror %s (simulated by %s): it needs %d mirror slot%s and %d of %d are free; this sim's "
            "sensors do not see it. Start the sim with a larger --mirrors (docs/sim.md)",
            robot,
            source or "another sim",
            needed,
            "" if needed == 1 else "s",
            mirrors.free,
            mirrors.slots,
        )

    def _on_sim(self, kind: str, peer_id: str, alive: bool) -> None:
        if alive:
            with self._state:
                self._departed.discard(peer_id)
                self._asked_at = float("-inf")  # a new sim: its robots are in the next description
            return
        with self.lock:
            with self._state:
                if len(self._departed) < MAX_DEPARTED:
                    self._departed.add(peer_id)
            gone = self.world.unmirror(source=peer_id)
        self._forget(gone, f"its sim {peer_id} left")

    def _forget(self, robots: list[str], why: str) -> None:
        if not robots:
            return
        with self._state:
            for r in robots:
                self._seen.pop(r, None)
        self.counters["hidden"] += len(robots)
        log.info("no longer mirroring %s: %s", ", ".join(robots), why)

    def _sweep_loop(self) -> None:
        while not self._stop.wait(min(0.5, self.stale_s / 2)):
            self.sweep()

    def sweep(self) -> list[str]:
        """Hide mirrors whose robot sent no pose for ``stale_s``; their ids."""
        now = self._clock()
        with self._state:
            stale = [r for r, t in self._seen.items() if now - t > self.stale_s]
        gone = []
        if stale:
            with self.lock:
                for r in stale:
                    gone += self.world.unmirror(r)
        self._forget(gone, f"no pose for {self.stale_s:g} s")
        return gone

    # ------------------------------------------------------------------ lifecycle

    def summary(self) -> str:
        """One line: how many robots were mirrored and how old their poses were on arrival (``bench shards`` reads it)."""
        lags = sorted(self.lag_ms)

        def q(p: float) -> float:
            return lags[min(len(lags) - 1, int(round(p / 100 * (len(lags) - 1))))] if lags else float("nan")

        c = self.counters
        return (
            f"mirrors: {c['shown']} shown, {c['hidden']} hidden, {self.world.mirrors.refused} without a slot; pose age on arrival "
            f"p50 {q(50):.1f} ms, p99 {q(99):.1f} ms over {len(lags)} poses"
        )

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self.counters["poses"]:
            log.info("%s", self.summary())
        self._stop.set()
        with self._state:
            subs = self._subs + list(self._arm_subs.values())
            self._arm_subs.clear()
        for sub in subs:
            try:
                sub.undeclare()
            except Exception:  # the session closed first
                pass
        if self._sweeper is not threading.current_thread():
            self._sweeper.join(timeout=2.0)

    def __enter__(self) -> "MirrorFeed":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
