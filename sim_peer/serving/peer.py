"""The sim peer: a :class:`~sim_peer.physics.world.SimWorld` served on the fabric.

The peer never asks what kind of robot it holds: it loops over the robots' hooks (:mod:`sim_peer.robot`).
Streams are what robots' ``streams()`` declare, grouped by rate, each group on its own
:class:`fabric.rate.RateLoop` (wall-clock rates, independent of the physics step; headers carry sim time;
:mod:`sim_peer.serving.streams`). With the built-in robots:

* ``joints`` - every robot's JointState; an arm's flange Pose goes out with it on the robot's ``pose`` key;
* ``pose`` - every mobile robot's base Pose (axle midpoint) with its velocities;
* ``scan`` - every LIDAR as a Scan, and the ultrasonic ring on ``sonar``.

Commands (:mod:`sim_peer.serving.commanding`) on ``rf/{world}/robot/{id}/cmd/*/by/{user}`` (the sender is the key's user; a payload naming
someone else is refused) pass through the :class:`fabric.gate.CommandGate`
first; anything refused or unusable is published as an ``Event(kind=EventKind.REJECT)`` under
``event/reject/{robot}`` with the reason, counted, and the robot keeps its last valid command.
A command for a robot this sim does not have is refused from its key alone, before it is
decoded or anything is kept for it, on the one fixed key ``event/reject``. Admitted commands
leave zenoh's callback thread at once: they wait in a bounded per-robot
:class:`~sim_peer.serving.inbox.CommandQueue` (the latest target wins, a stop or reset is never
dropped) that a worker thread applies, so a flood on one key cannot hold up another robot.
The gate is asked again when a command is applied, so a command admitted just before its sender lost the
robot is refused rather than applied after the stop. A robot that loses its owner (a release, a handover, a
take-over, the end of her lease, her departure: the gate's ``watch_stops``) stops: the stop takes the place
of her pending commands in the robot's queue before anyone hears of the new owner, so it never lands on the
new owner's first command; a base brakes within its limits, an arm holds where it is (``SimRobot.halt``), and
a robot that was moving says why as ``Event(kind=EventKind.OWNER_STOP)`` (docs/ownership.md).
Refusals and bad payloads are reported at most a few times per reason per interval
(:meth:`fabric.reports.Reports.emit` with ``limit``), with the count of the rest (:mod:`sim_peer.serving.reporting`).
Clamped commands are applied and reported as ``Event(kind=EventKind.CLAMP)``. A command kind a robot's
``commands()`` does not list is refused with reason ``unsupported``. What robots and sensors note while
stepping (a path followed to its end, a bumper stop) goes out as events. Scene objects move on
``rf/{world}/object/{id}/pose/by/{user}``. ``rf/{world}/srv/world`` answers a :class:`WorldInfo` made of
the robots' ``describe()``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import replace
from typing import Any

from fabric import keys
from fabric.gate import CommandGate, OpenGate
from fabric.interfaces import Command, ObjectInfo, Pose, WorldInfo
from fabric.limits import quote
from fabric.rate import Clock
from fabric.session import Fabric, undeclare_all
from sim_peer.serving.commanding import CommandPipeline
from sim_peer.shards.mirroring import MirrorFeed
from sim_peer.physics.pacing import Pacer
from sim_peer.serving.reporting import Reporter
from sim_peer.serving.streams import DEFAULT_RATES, StreamLoops
from sim_peer.physics.world import SimWorld

log = logging.getLogger("robofabric.sim")

WAKE_S = 0.01
"""The least wall time between two chunks of physics at real time: five 2 ms steps a wake-up, not one. Stepping
each step as it came due woke the physics thread 500 times a second, and its wake-ups (the lock, the motion
check, the notes) were most of an idle sim's CPU (a sim that nobody drove: 15 % of a core, 9 of it that thread);
a command waits 5 ms more on average, the same steps are taken at the same sim times, and the streams (100 Hz at
most) still see a new state each period."""


class SimPeer:
    """Serve ``world`` on ``fabric``. ``start()`` runs physics in a thread; ``run()`` runs it in the caller's.

    The peer owns neither the fabric nor the gate: whoever made them closes them. Its parts: ``report`` (events
    and refusals), ``commands`` (the command pipeline), ``streams`` (the stream loops), ``mirror_feed`` (the other
    sims' robots, once open).
    """

    def __init__(
        self,
        fabric: Fabric,
        world: SimWorld,
        *,
        gate: CommandGate | None = None,
        rates: dict[str, float] | None = None,
        speed: float | None = 1.0,
        clock: Clock | None = None,
        objects: bool = True,
    ) -> None:
        self.fabric = fabric
        # the scene objects' authority (describes them, reports bad poses): the first sim of a world; the others of
        # a sharded world mirror them, moving them on the same users' poses without a word, so the one that adopts
        # them when their authority goes has them where they were (docs/sim.md, "Several sims, one world")
        self.objects = objects
        self.other_sims: set[str] = set()  # other live sims: a command for a robot none of ours may be theirs
        self.world = world
        self.gate: CommandGate = gate if gate is not None else OpenGate()
        self.lock = threading.RLock()
        self.counters: Counter[str] = Counter()
        self.streams = StreamLoops(fabric, world, self.lock, self.counters, rates)
        self.rates = self.streams.rates
        self.speed = speed
        self.pacer = Pacer(world.dt, speed, clock=clock, wake_s=WAKE_S)
        self._moving = {rid: False for rid in world.robots}
        world.notes.take()  # news from before the peer (a standby's catch-up steps) is not the world's to tell
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._opened = False
        self._closed = False
        self.report = Reporter(fabric, world, self.counters)
        self.commands = CommandPipeline(
            fabric,
            world,
            self.lock,
            self.gate,
            self.report,
            counters=self.counters,
            stop=self._stop,
            others=lambda: bool(self.other_sims),
        )
        self.mirror_feed: MirrorFeed | None = None  # the other sims' robots in this world, once open (mirror slots)
        self._declared: list[Any] = []  # what open() declared on the shared session: close() takes it away

    # ------------------------------------------------------------------ lifecycle

    def open(self) -> "SimPeer":
        """Declare subscriptions and the world service, start the stream loops. Physics is not stepped yet."""
        if self._opened:
            return self
        self._opened = True
        f, w = self.fabric, self.fabric.world
        d = self._declared
        d.append(f.rpc.serve(keys.srv(w, "world"), self._on_world_query))
        self.commands.start()
        d.append(f.watch_peers(self._on_sim, kind="sim"))
        watch_stops = getattr(self.gate, "watch_stops", None)  # a gate of before the rule may lack it
        if watch_stops is not None:
            watch_stops(self.commands.on_owner_lost)
        watch_resets = getattr(self.gate, "watch_resets", None)  # an instructor's reset (ownership.staff)
        if watch_resets is not None:
            watch_resets(self.commands.on_reset)
        d.append(f.subscribe_raw(keys.robot_cmd_all(w), self.commands.on_sample))
        for obj in self.world.objects:
            # no history here: the authority's start must not wait on other peers' caches (with
            # history=True a sim started under load answered nothing for 30 s in two CI runs)
            d.append(f.subscribe(keys.object_pose_all(w, obj), self.apply_object_pose, expected=Pose))
        for rid in self.world.robots:
            self._safe_gate_motion(rid, False)
        self.streams.start()
        if self.world.mirrors.slots:
            self.mirror_feed = MirrorFeed(f, self.world, self.lock)
        return self

    def start(self, duration: float | None = None) -> "SimPeer":
        """Open and step physics in a daemon thread until :meth:`close` (or ``duration`` of sim time)."""
        self.open()
        thread = threading.Thread(target=self.run, args=(self._stop, duration), name="sim-physics", daemon=True)
        # known only once started: a thread not yet started is not alive, and a host that looked at ``finished`` in
        # between (a take-over starting its peer under load) read a peer that had not begun as one that had ended,
        # and stopped the sim it had just made primary (the soak's sim-b: "0 steps", exit 0)
        thread.start()
        self._thread = thread
        return self

    def run(self, stop: threading.Event | None = None, duration: float | None = None) -> None:
        """Step the world, paced, until ``stop`` is set or sim time reaches ``duration``."""
        self.open()
        stop = stop or self._stop
        end_steps = None if duration is None else self.world.steps + int(round(duration / self.world.dt))
        while not stop.is_set() and not self._stop.is_set():
            n = self.pacer.due()
            if end_steps is not None:
                n = min(n, end_steps - self.world.steps)
            if n <= 0:
                if end_steps is not None and self.world.steps >= end_steps:
                    break
                stop.wait(min(self.pacer.wait(), 2 * WAKE_S) or 0.0005)
                continue
            with self.lock:
                self.world.step(n)
                changes = self._motion_changes()
                notes = self.world.notes.take()
            self.pacer.done(n)
            self.counters["steps"] += n
            for rid, moving in changes:
                self._safe_gate_motion(rid, moving)
            for rid, note in notes:
                if note.counter:
                    self.counters[note.counter] += 1
                self.report.event(note.kind, rid, note.reason, severity=note.severity, data=dict(note.data) or None)
            if self.speed is None:
                time.sleep(0)  # let streams and commands have the interpreter between chunks

    @property
    def finished(self) -> bool:
        """Whether physics stepped in the peer's own thread (``start()``) has ended: its duration was reached,
        or the peer was closed."""
        return self._thread is not None and not self._thread.is_alive()

    def close(self) -> None:
        """Stop physics and streams, and take away the subscriptions and the world service it declared (a sim
        rebuilding its world on the same session, docs/sim.md "Moving a robot between sims"); idempotent. The
        fabric and the gate stay open."""
        if self._closed:
            return
        self._closed = True
        undeclare_all(self._declared)
        self._stop.set()
        self.commands.wake()
        if self._thread is not None:
            self._thread.join(5.0)
        self.commands.join(5.0)
        self.streams.stop()
        if self.mirror_feed is not None:
            self.mirror_feed.close()

    def __enter__(self) -> "SimPeer":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ state

    def last_state(self, robot_id: str) -> dict[str, Any]:
        """A robot's last known state as a small dict of plain values (for ownership records)."""
        with self.lock:
            return self.world.state(robot_id)

    def world_info(self) -> WorldInfo:
        with self.lock:
            robots = [replace(r.describe(), sim=self.fabric.peer_id) for r in self.world.robots.values()]
            objects = []
            for o in self.world.scene.objects if self.objects else ():
                pos, quat = self.world.objects.pose(o.id)
                objects.append(ObjectInfo(o.id, o.kind, o.policy, pos, quat))
            return WorldInfo(
                world=self.fabric.world,
                scene=self.world.scene.name,
                timestep=self.world.dt,
                rates=dict(self.rates),
                robots=tuple(robots),
                objects=tuple(objects),
                header=self.fabric.header("srv/world", stamp=self.world.time),
            )

    def _motion_changes(self) -> list[tuple[str, bool]]:
        """(robot, new motion state) for robots that started or stopped moving."""
        out = []
        for rid, r in self.world.robots.items():
            moving = r.moving
            if moving != self._moving[rid]:
                out.append((rid, moving))
                self._moving[rid] = moving
        return out

    def _safe_gate_motion(self, rid: str, moving: bool) -> None:
        try:
            self.gate.update_motion(rid, moving)
        except Exception:
            self.counters["gate_errors"] += 1
            log.exception("gate.update_motion(%s) failed", rid)

    # ------------------------------------------------------------------ commands and object poses

    def superseded(self) -> int:
        """Admitted commands a later one of the same robot replaced before they were applied."""
        return self.commands.superseded()

    def apply_command(self, key: str, cmd: Command) -> None:
        """Admit and apply one decoded command now, in the caller's thread (a standby replaying what users
        sent at a take-over; tests; in-process use)."""
        self.commands.apply(key, cmd)

    def apply_object_pose(self, key: str, pose: Pose) -> None:
        """Set a scene object's pose from a user's ``object/{id}/pose/by/{user}`` sample, now."""
        obj = keys.parse(key).subject  # one subscription per scene object: never a made-up id
        if pose.frame not in ("world", ""):
            if self.objects:  # the objects' authority reports; a sim mirroring them drops it without a word
                frame = (
                    pose.frame
                )  # client text (up to the codec's string limit): quoted short, built only when reported
                self.report.reject(
                    obj, "pose", "bad_frame", lambda: f"object poses must be in the world frame, got {quote(frame)}"
                )
            return
        try:
            with self.lock:
                self.world.objects.set_pose(obj, pose.position, pose.quaternion)
        except (KeyError, ValueError) as exc:
            if self.objects:
                self.report.reject(obj, "pose", "bad_object_pose", str(exc))
            return
        self.counters["object_updates" if self.objects else "object_mirrored"] += 1

    def _on_sim(self, kind: str, peer_id: str, alive: bool) -> None:
        if peer_id != self.fabric.peer_id:
            (self.other_sims.add if alive else self.other_sims.discard)(peer_id)

    def _on_world_query(self, key: str, request: Any) -> WorldInfo:
        return self.world_info()


__all__ = ["SimPeer", "DEFAULT_RATES"]
