"""The sim peer: a :class:`~sim_peer.world.SimWorld` served on the fabric.

The peer never asks what kind of robot it holds: it loops over the robots' hooks (:mod:`sim_peer.robot`).
Streams are what robots' ``streams()`` declare, grouped by rate, each group on its own
:class:`fabric.rate.RateLoop` (wall-clock rates, independent of the physics step; headers carry sim time).
With the built-in robots:

* ``joints`` - every robot's JointState; an arm's flange Pose goes out with it on the robot's ``pose`` key;
* ``pose`` - every mobile robot's base Pose (axle midpoint) with its velocities;
* ``scan`` - every LIDAR as a Scan, and the ultrasonic ring on ``sonar``.

Commands on ``rf/{world}/robot/{id}/cmd/*/by/{user}`` (the sender is the key's user; a payload naming
someone else is refused) pass through the :class:`fabric.gate.CommandGate`
first; anything refused or unusable is published as an ``Event(kind=EventKind.REJECT)`` under
``event/reject/{robot}`` with the reason, counted, and the robot keeps its last valid command.
A command for a robot this sim does not have is refused from its key alone, before it is
decoded or anything is kept for it, on the one fixed key ``event/reject``. Admitted commands
leave zenoh's callback thread at once: they wait in a bounded per-robot
:class:`~sim_peer.inbox.CommandQueue` (the latest target wins, a stop or reset is never
dropped) that a worker thread applies, so a flood on one key cannot hold up another robot.
The gate is asked again when a command is applied, so a command admitted just before its sender lost the
robot is refused rather than applied after the stop. A robot that loses its owner (a release, a handover, a
take-over, the end of her lease, her departure: the gate's ``watch_stops``) stops: the stop takes the place
of her pending commands in the robot's queue before anyone hears of the new owner, so it never lands on the
new owner's first command; a base brakes within its limits, an arm holds where it is (``SimRobot.halt``), and
a robot that was moving says why as ``Event(kind=EventKind.OWNER_STOP)`` (docs/ownership.md).
Refusals and bad payloads are reported at most a few times per reason per interval
(:meth:`fabric.session.Fabric.emit` with ``limit``), with the count of the rest.
Clamped commands are applied and reported as ``Event(kind=EventKind.CLAMP)``. A command kind a robot's
``commands()`` does not list is refused with reason ``unsupported``. What robots and sensors note while
stepping (a path followed to its end, a bumper stop) goes out as events. Scene objects move on
``rf/{world}/object/{id}/pose/by/{user}``. ``rf/{world}/srv/world`` answers a :class:`WorldInfo` made of
the robots' ``describe()``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import logging
import threading
import time
from collections import Counter
from typing import Any, Callable

import zenoh

from fabric import keys

from fabric.codec import DecodeError, decode
from fabric.gate import CommandGate, OpenGate
from fabric.interfaces import Command, Event, EventKind, ObjectInfo, Pose, WorldInfo
from fabric.limits import clip, is_valid_user, quote
from fabric.rate import Clock, RateLoop
from fabric.session import Fabric, undeclare_all
from sim_peer.controllers import Clamp, CommandRejected
from sim_peer.inbox import CommandQueue
from sim_peer.mirroring import MirrorFeed
from sim_peer.pacing import Pacer
from sim_peer.robot import Build, CommandHandler, Stream, body_mismatch
from sim_peer.world import SimWorld

log = logging.getLogger("robofabric.sim")


@dataclass(frozen=True, slots=True)
class Halt:
    """A stop the sim queues itself when a robot loses its owner ``user`` (``reason`` says how)."""

    user: str
    reason: str

DEFAULT_RATES = {"joints": 100.0, "pose": 50.0, "scan": 20.0}


class SimPeer:
    """Serve ``world`` on ``fabric``. ``start()`` runs physics in a thread; ``run()`` runs it in the caller's.

    The peer owns neither the fabric nor the gate: whoever made them closes them.
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
        self._other_sims: set[str] = set()  # other live sims: a command for a robot none of ours may be theirs
        self.world = world
        self.gate: CommandGate = gate if gate is not None else OpenGate()
        self.rates = {**DEFAULT_RATES, **(rates or {})}
        self._streams = self._gather_streams(fabric.world, world)
        for group, entries in self._streams.items():
            self.rates.setdefault(group, entries[0][1].hz)
        self._handlers: dict[str, dict[str, CommandHandler]] = {rid: dict(r.commands()) for rid, r in world.robots.items()}
        self.speed = speed
        self.pacer = Pacer(world.dt, speed, clock=clock)
        self.lock = threading.RLock()
        self.counters: Counter[str] = Counter()
        self._moving = {rid: False for rid in world.robots}
        world.take_notes()  # news from before the peer (a standby's catch-up steps) is not the world's to tell
        self._loops: list[RateLoop] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._opened = False
        self._closed = False
        self._queues: dict[str, CommandQueue[Command | Halt]] = {rid: CommandQueue() for rid in world.robots}
        self._queued = threading.Condition(threading.Lock())
        self._worker: threading.Thread | None = None
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
        self._worker = threading.Thread(target=self._drain, name="sim-commands", daemon=True)
        self._worker.start()
        d.append(f.watch_peers(self._on_sim, kind="sim"))
        watch_stops = getattr(self.gate, "watch_stops", None)  # a gate of before the rule may lack it
        if watch_stops is not None:
            watch_stops(self._on_owner_lost)
        d.append(f.subscribe_raw(keys.robot_cmd_all(w), self._on_command_sample))
        for obj in self.world.objects:
            # no history here: the authority's start must not wait on other peers' caches (with
            # history=True a sim started under load answered nothing for 30 s in two CI runs)
            d.append(f.subscribe(keys.object_pose_all(w, obj), self._on_object, expected=Pose))
        for rid in self.world.robots:
            self._safe_gate_motion(rid, False)
        for group, entries in self._streams.items():
            tick = self._guard(group, self._publisher(entries))
            self._loops.append(RateLoop(self.rates[group], tick, name=f"sim-{group}").start())
        if self.world.mirrors.slots:
            self.mirror_feed = MirrorFeed(f, self.world, self.lock)
        return self

    def start(self, duration: float | None = None) -> "SimPeer":
        """Open and step physics in a daemon thread until :meth:`close` (or ``duration`` of sim time)."""
        self.open()
        self._thread = threading.Thread(target=self.run, args=(self._stop, duration), name="sim-physics", daemon=True)
        self._thread.start()
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
                stop.wait(min(self.pacer.wait(), 0.005) or 0.0005)
                continue
            with self.lock:
                self.world.step(n)
                changes = self._motion_changes()
                notes = self.world.take_notes()
            self.pacer.done(n)
            self.counters["steps"] += n
            for rid, moving in changes:
                self._safe_gate_motion(rid, moving)
            for rid, note in notes:
                if note.counter:
                    self.counters[note.counter] += 1
                self._event(note.kind, rid, note.reason, severity=note.severity, data=dict(note.data) or None)
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
        with self._queued:
            self._queued.notify_all()
        if self._thread is not None:
            self._thread.join(5.0)
        if self._worker is not None:
            self._worker.join(5.0)
        for loop in self._loops:
            loop.stop()
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
            for o in (self.world.scene.objects if self.objects else ()):
                pos, quat = self.world.object_pose(o.id)
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

    # ------------------------------------------------------------------ commands

    def _event(self, kind: str, robot: str, reason: str, *, user: str = "", severity: str = "warning", data: dict | None = None,
               limit: str | None = None) -> None:
        """Publish an event on ``event/{kind}/{robot}`` (``event/{kind}`` for ids this sim does not have).

        ``limit``: a rate-limit key of fixed words (fabric.session.Fabric.should_report), checked before
        anything is built, so a flood of refusals costs a counter each."""
        if limit is not None:
            suppressed = self.fabric.should_report(limit)
            if suppressed is None:
                return
            if suppressed:
                data = {**(data or {}), "suppressed": suppressed}
        key_parts = (kind, robot) if robot in self.world.robots or robot in self.world.objects else (kind,)
        ev = Event(
            kind=kind, reason=reason, object=robot, user=user, severity=severity, data=data or {},
            header=self.fabric.header("event", stamp=self.world.time),
        )
        self.fabric.emit(ev, *key_parts)

    def _reject(self, robot: str, command: str, reason: str | Callable[[], str], detail: str | Callable[[], str], user: str = "",
                *, code: str | None = None) -> None:
        """Count and report a refusal. ``code`` (default ``reason``) is the counter and rate-limit name:
        a fixed word, never client text, so made-up users or ids cannot grow the counters. ``reason``
        and ``detail`` may be callables, built only when the refusal is reported."""
        code = code or ("refused" if callable(reason) else reason)
        self.counters["rejected"] += 1
        self.counters[f"rejected:{code}"] += 1
        known = robot in self.world.robots or robot in self.world.objects
        suppressed = self.fabric.should_report(f"reject:{robot if known else '?'}:{code}")
        if suppressed is None:
            return
        # code: which check refused it ("refused": the ownership gate), so a client tells NotOwner from a bad command
        data = {"command": command, "code": code, "detail": detail() if callable(detail) else detail}
        if suppressed:
            data["suppressed"] = suppressed
        self._event(EventKind.REJECT, robot if known else clip(robot, 64), reason() if callable(reason) else reason, user=user, data=data)

    def _on_command_sample(self, sample: zenoh.Sample) -> None:
        """Zenoh's callback: refuse unknown robots from the key alone, decode, admit, queue. Never applies."""
        if sample.kind != zenoh.SampleKind.PUT:
            return
        key = str(sample.key_expr)
        self.fabric.counters["received"] += 1
        try:
            parsed = keys.parse(key)
        except ValueError as exc:
            self.counters["commands"] += 1
            self._reject("", "?", "bad_key", clip(str(exc)))
            return
        rid = parsed.subject
        if rid not in self._queues:  # undecoded: the sender is not known, nothing is kept
            if self._other_sims:  # a sharded world: another sim's robot (or one nobody serves) is not ours to refuse
                self.counters["not_mine"] += 1
                return
            self.counters["commands"] += 1
            self._reject(rid, parsed.leaf, "unknown_robot", lambda: f"no robot {quote(rid, 64)} here; robots: {', '.join(self.world.robots)}")
            return
        try:
            cmd = decode(sample.payload.to_bytes(), Command)
        except DecodeError as exc:
            self.fabric.bad_payload(key, exc, where=keys.robot_cmd_all(self.fabric.world, rid))
            return
        admitted = self._admit(key, cmd)
        if admitted is None:
            return
        name, _ = admitted
        with self._queued:
            self._queues[rid].put(name, cmd)
            self._queued.notify()

    def _drain(self) -> None:
        """The command worker: apply what the queues hold, robot by robot, until :meth:`close`."""
        while not self._stop.is_set():
            with self._queued:
                batch = [(rid, q.take()) for rid, q in self._queues.items() if q]
                if not batch:
                    self._queued.wait(0.5)
                    continue
            for rid, items in batch:
                for name, cmd in items:
                    try:
                        if isinstance(cmd, Halt):
                            self._halt(rid, cmd)
                        elif self._still_admitted(rid, name, cmd):
                            self._execute(rid, name, cmd)
                    except Exception:
                        self.counters["command_errors"] += 1
                        log.exception("command %s for %s failed", name, rid)

    def _on_owner_lost(self, robot: str, user: str, reason: str) -> None:
        """The gate's word that ``robot`` lost its owner: its stop goes into the robot's queue now, in the
        gate's call (before the new owner can know her epoch), superseding the former owner's pending commands."""
        queue = self._queues.get(robot)
        if queue is None or self._closed:
            return
        with self._queued:
            queue.put("stop", Halt(user, reason))
            self._queued.notify()

    def _halt(self, rid: str, halt: Halt) -> None:
        """Stop a robot whose owner let go (:meth:`SimRobot.halt`); say why when it was moving."""
        with self.lock:
            robot = self.world.robots[rid]
            moving = robot.moving
            robot.halt()
        self.counters["owner_stops"] += 1
        if moving:
            self._event(EventKind.OWNER_STOP, rid, halt.reason, user=halt.user, severity="info")

    def _still_admitted(self, rid: str, name: str, cmd: Command) -> bool:
        """Ask the gate again as the command is applied: its sender may have lost the robot since it came."""
        refusal = self._gate_refusal(rid, cmd)
        if refusal:
            self._reject(rid, name, refusal, f"the gate refused {cmd.user}'s {name} command (epoch {cmd.epoch}) as it was applied",
                         cmd.user, code="refused")
            return False
        return True

    def _gate_refusal(self, rid: str, cmd: Command) -> str | None:
        """The gate's reason to refuse ``cmd`` now (None: admitted); a failing gate refuses, and says so."""
        try:
            return self.gate.admit(rid, cmd)
        except Exception as exc:
            log.exception("gate.admit failed")
            return f"gate error: {clip(str(exc))}"

    def superseded(self) -> int:
        """Admitted commands a later one of the same robot replaced before they were applied."""
        with self._queued:
            return sum(q.superseded for q in self._queues.values())

    def _admit(self, key: str, cmd: Command) -> tuple[str, Any] | None:
        """Check a decoded command (robot, body, gate); ``(name, robot)`` when it may be applied."""
        self.counters["commands"] += 1
        try:
            parsed = keys.parse(key)
        except ValueError as exc:
            self._reject("", "?", "bad_key", clip(str(exc)), cmd.user)
            return None
        rid, name, sender = parsed.subject, parsed.leaf, parsed.user
        robot = self.world.robots.get(rid)
        if robot is None:
            self._reject(rid, name, "unknown_robot", lambda: f"no robot {quote(rid, 64)} here; robots: {', '.join(self.world.robots)}", cmd.user)
            return None
        if cmd.user != sender:
            # the key names the sender (a router's access control vouches for it); a payload claiming
            # someone else is a forgery or a bug, never a command
            self._reject(rid, name, "user_mismatch", f"the command names {quote(cmd.user, 64)} but was sent on {quote(sender, 64)}'s key",
                         sender if is_valid_user(sender) else "")
            return None
        mismatch = body_mismatch(name, cmd.body)
        if mismatch:
            self._reject(rid, name, "wrong_body", mismatch, cmd.user)
            return None
        refusal = self._gate_refusal(rid, cmd)
        if refusal:
            self._reject(rid, name, refusal, f"the gate refused {cmd.user}'s {name} command (epoch {cmd.epoch})", cmd.user,
                         code="refused")
            return None
        return name, robot

    def apply_command(self, key: str, cmd: Command) -> None:
        """Admit and apply one decoded command now, in the caller's thread (a standby replaying what users
        sent at a take-over; tests; in-process use)."""
        admitted = self._admit(key, cmd)
        if admitted is not None:
            self._execute(keys.parse(key).subject, admitted[0], cmd)

    def apply_object_pose(self, key: str, pose: Pose) -> None:
        """Set a scene object's pose from a user's ``object/{id}/pose/by/{user}`` sample, now."""
        self._on_object(key, pose)

    def _execute(self, rid: str, name: str, cmd: Command) -> None:
        try:
            with self.lock:
                clamp = self._apply(rid, name, cmd.body)
        except CommandRejected as exc:
            self._reject(rid, name, exc.reason, str(exc), cmd.user)
            return
        self.counters["accepted"] += 1
        if clamp is not None:
            self.counters["clamped"] += 1
            self._event(
                EventKind.CLAMP, rid, "out_of_range" if name == "joints" else "over_limit", user=cmd.user,
                data={"command": name, "what": list(clamp.what), "requested": list(clamp.requested), "applied": list(clamp.applied)},
                limit=f"clamp:{rid}",
            )

    def _apply(self, rid: str, name: str, body: Any) -> Clamp | None:
        handler = self._handlers[rid].get(name)
        if handler is None:
            robot = self.world.robots[rid]
            raise CommandRejected("unsupported", f"robot {rid} ({robot.desc.name}) does not take {name} commands; "
                                                 f"it takes {', '.join(self._handlers[rid]) or 'none'}")
        return handler(body)

    def _on_object(self, key: str, pose: Pose) -> None:
        obj = keys.parse(key).subject  # one subscription per scene object: never a made-up id
        if pose.frame not in ("world", ""):
            if self.objects:  # the objects' authority reports; a sim mirroring them drops it without a word
                frame = pose.frame  # client text (up to the codec's string limit): quoted short, built only when reported
                self._reject(obj, "pose", "bad_frame", lambda: f"object poses must be in the world frame, got {quote(frame)}")
            return
        try:
            with self.lock:
                self.world.set_object_pose(obj, pose.position, pose.quaternion)
        except (KeyError, ValueError) as exc:
            if self.objects:
                self._reject(obj, "pose", "bad_object_pose", str(exc))
            return
        self.counters["object_updates" if self.objects else "object_mirrored"] += 1

    def _on_sim(self, kind: str, peer_id: str, alive: bool) -> None:
        if peer_id != self.fabric.peer_id:
            (self._other_sims.add if alive else self._other_sims.discard)(peer_id)

    def _on_world_query(self, key: str, request: Any) -> WorldInfo:
        return self.world_info()

    # ------------------------------------------------------------------ streams

    def _guard(self, name: str, fn: Callable[[float], None]) -> Callable[[float], None]:
        def tick(now: float) -> None:
            if self.fabric.closed:
                return
            try:
                fn(now)
            except Exception:
                self.counters[f"stream_errors:{name}"] += 1
                log.exception("stream %s failed", name)

        return tick

    @staticmethod
    def _gather_streams(world_name: str, world: SimWorld) -> dict[str, list[tuple[str, Stream]]]:
        """Every robot's streams by rate group, each with its key; streams on keys fabric.keys does not know are
        left out with a warning (a new stream name is a protocol change: fabric.keys.ROBOT_STREAMS)."""
        groups: dict[str, list[tuple[str, Stream]]] = {g: [] for g in DEFAULT_RATES}
        for rid, r in world.robots.items():
            for st in r.streams():
                if st.name not in keys.ROBOT_STREAMS:
                    log.warning("robot %s: stream %r is not a robot stream of fabric.keys; not published", rid, st.name)
                    continue
                groups.setdefault(st.rate, []).append((keys.robot_stream(world_name, rid, st.name), st))
        return {g: entries for g, entries in groups.items() if entries}

    def _publisher(self, entries: list[tuple[str, Stream]]) -> Callable[[float], None]:
        """One rate group's tick: read every stream under the lock, then build and publish outside it."""
        positions = any(st.positions for _, st in entries)

        def publish(now: float) -> None:
            world = self.world
            out: list[tuple[str, Build]] = []
            with self.lock:
                stamp = world.time
                if positions:
                    world.sync()
                physics = world.physics
                for key, st in entries:
                    build = st.read(physics)
                    if build is not None:
                        out.append((key, build))
            for key, build in out:
                self.fabric.publish(key, build(self.fabric.header(key, stamp=stamp)))

        return publish


__all__ = ["SimPeer", "DEFAULT_RATES"]
