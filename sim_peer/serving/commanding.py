"""Commands into a sim's robots: refused from the key, decoded, admitted by the gate, queued, applied.

Commands on ``rf/{world}/robot/{id}/cmd/*/by/{user}`` (the sender is the key's user; a payload naming someone
else is refused) pass through the :class:`fabric.gate.CommandGate` first; anything refused or unusable is
reported (:class:`sim_peer.serving.reporting.Reporter`) and the robot keeps its last valid command. A command for a
robot this sim does not have is refused from its key alone, before it is decoded or anything is kept for it
(in a world of several sims it may be another's: counted as ``not_mine``, not refused). Admitted commands leave
zenoh's callback thread at once: they wait in a bounded per-robot :class:`~sim_peer.serving.inbox.CommandQueue` (the
latest target wins, a stop or reset is never dropped) that a worker thread applies, so a flood on one key
cannot hold up another robot. The gate is asked again when a command is applied, so a command admitted just
before its sender lost the robot is refused rather than applied after the stop. A robot that loses its owner
(the gate's ``watch_stops``) stops: the stop takes the place of her pending commands in the robot's queue. A sim
that hears no one (:mod:`sim_peer.replica.deaf_stop`) stops every robot the same way and refuses commands until it hears
again (:meth:`CommandPipeline.hold`, :meth:`CommandPipeline.resume`). A command is applied once by its id
(:mod:`sim_peer.serving.command_ids`): a copy sent again by a client riding out such a hold is counted as ``duplicates``.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from dataclasses import dataclass
from typing import Any, Callable

import zenoh

from fabric import keys
from fabric.codec import DecodeError, decode
from fabric.gate import CommandGate
from fabric.interfaces import Command, EventKind
from fabric.limits import clip, is_valid_user, quote
from sim_peer.serving.command_ids import RecentIds
from sim_peer.controllers import Clamp, CommandRejected
from sim_peer.serving.inbox import CommandQueue
from sim_peer.serving.reporting import Reporter
from sim_peer.robot import CommandHandler, body_mismatch
from sim_peer.physics.world import SimWorld

log = logging.getLogger("robofabric.sim")

__all__ = ["CommandPipeline", "Halt"]


@dataclass(frozen=True, slots=True)
class Halt:
    """A stop the sim queues itself when a robot loses its owner ``user`` (``reason`` says how)."""

    user: str
    reason: str
    reset: bool = False  # an instructor's reset (ownership.staff): back to the start rather than a stop


class CommandPipeline:
    """Admit and apply the commands of ``world``'s robots under ``lock``; a worker thread drains the queues."""

    def __init__(
        self,
        fabric: Any,
        world: SimWorld,
        lock: threading.RLock,
        gate: CommandGate,
        report: Reporter,
        *,
        counters: Counter[str],
        stop: threading.Event,
        others: Callable[[], bool],
    ) -> None:
        self.fabric, self.world, self.lock, self.gate, self.report = fabric, world, lock, gate, report
        self.counters = counters
        self._stop = stop  # the peer's: set when it closes
        self._others = others  # whether other sims share the world (a command for a robot none of ours may be theirs)
        self._handlers: dict[str, dict[str, CommandHandler]] = {
            rid: dict(r.commands()) for rid, r in world.robots.items()
        }
        self._queues: dict[str, CommandQueue[Command | Halt]] = {rid: CommandQueue() for rid in world.robots}
        self._queued = threading.Condition(threading.Lock())
        self._worker: threading.Thread | None = None
        self._held = ""  # why every robot holds and commands are refused ('' : they are not)
        self._applied = {rid: RecentIds() for rid in world.robots}  # a command sent again is applied once
        self._last_user: dict[str, str] = {}  # robot -> who sent its last admitted command
        self._stopped: dict[str, str] = {}  # robot -> whose motion, pending or refused command the hold stopped

    def start(self) -> None:
        self._worker = threading.Thread(target=self._drain, name="sim-commands", daemon=True)
        self._worker.start()

    def wake(self) -> None:
        """Let the worker see the peer's stop now."""
        with self._queued:
            self._queued.notify_all()

    def join(self, timeout: float) -> None:
        if self._worker is not None:
            self._worker.join(timeout)

    def superseded(self) -> int:
        """Admitted commands a later one of the same robot replaced before they were applied."""
        with self._queued:
            return sum(q.superseded for q in self._queues.values())

    def on_sample(self, sample: zenoh.Sample) -> None:
        """Zenoh's callback: refuse unknown robots from the key alone, decode, admit, queue. Never applies."""
        if sample.kind != zenoh.SampleKind.PUT:
            return
        key = str(sample.key_expr)
        self.fabric.counters["received"] += 1
        try:
            parsed = keys.parse(key)
        except ValueError as exc:
            self.counters["commands"] += 1
            self.report.reject("", "?", "bad_key", clip(str(exc)))
            return
        rid = parsed.subject
        if rid not in self._queues:  # undecoded: the sender is not known, nothing is kept
            if self._others():  # a sharded world: another sim's robot (or one nobody serves) is not ours to refuse
                self.counters["not_mine"] += 1
                return
            self.counters["commands"] += 1
            self.report.reject(
                rid,
                parsed.leaf,
                "unknown_robot",
                lambda: f"no robot {quote(rid, 64)} here; robots: {', '.join(self.world.robots)}",
            )
            return
        try:
            cmd = decode(sample.payload.to_bytes(), Command)
        except DecodeError as exc:
            self.fabric.reports.bad_payload(key, exc, where=keys.robot_cmd_all(self.fabric.world, rid))
            return
        admitted = self._admit(key, cmd)
        if admitted is None:
            return
        with self._queued:
            self._queues[rid].put(admitted, cmd)
            self._last_user[rid] = cmd.user
            self._queued.notify()

    def on_owner_lost(self, robot: str, user: str, reason: str) -> None:
        """The gate's word that ``robot`` lost its owner: its stop goes into the robot's queue now, in the
        gate's call (before the new owner can know her epoch), superseding the former owner's pending commands."""
        queue = self._queues.get(robot)
        if queue is None or self._stop.is_set():
            return
        with self._queued:
            queue.put("stop", Halt(user, reason))
            self._queued.notify()

    def on_reset(self, robot: str, user: str, reason: str) -> None:
        """The gate's word that an instructor reset ``robot``: it goes back to its start (its own ``reset`` command),
        superseding whatever is pending; its owner keeps it."""
        queue = self._queues.get(robot)
        if queue is None or self._stop.is_set():
            return
        with self._queued:
            queue.put("reset", Halt(user, reason, reset=True))
            self._queued.notify()

    @property
    def held(self) -> str:
        """Why the robots hold and commands are refused (:meth:`hold`); empty when they are not."""
        return self._held

    def hold(self, reason: str) -> None:
        """Stop every robot as a release stops it (a base brakes, an arm holds where it is) and refuse every command
        until :meth:`resume`: what a sim simulates while nobody hears it is lost when another takes the world over,
        so it must not move its robots on meanwhile."""
        with self._queued:
            self._held = reason or "held"
            for rid, q in self._queues.items():
                user = self._last_user.get(rid)
                if user and (q or self.world.robots[rid].underway):
                    self._stopped[rid] = user
                q.put("stop", Halt("", self._held))  # its halt forgets the ids applied (_halt)
            self._queued.notify()

    def resume(self) -> None:
        """Accept commands again (the robots stay where :meth:`hold` stopped them until their owners send more). The
        sender of the last command the hold stopped on each robot (its robot underway, the command queued, or refused
        meanwhile) is told now, with a ``held`` refusal, that it was not carried out: a client that awaits it sends it again (:mod:`user_peer.pause`)."""
        with self._queued:
            self._held = ""
            stopped, self._stopped = self._stopped, {}
        for rid, user in stopped.items():
            self.report.reject(
                rid,
                "?",
                "held",
                "the sim held its robots and stopped this one before its command was done; "
                "it hears again: send the command again",
                user,
                code="resumed",
            )

    def apply(self, key: str, cmd: Command) -> None:
        """Admit and apply one decoded command now, in the caller's thread."""
        name = self._admit(key, cmd)
        if name is not None:
            rid = keys.parse(key).subject
            self._last_user[rid] = cmd.user
            self._execute(rid, name, cmd)

    def _drain(self) -> None:
        """The command worker: apply what the queues hold, robot by robot, until the peer stops."""
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

    def _halt(self, rid: str, halt: Halt) -> None:
        """Stop a robot whose owner let go, or that a hold stops (:meth:`SimRobot.halt`); say why when it was moving.

        What it stopped is to be done again when sent again: the ids applied are forgotten here, in the worker's
        order, not when the hold is asked. A command the worker had taken just before a hold, applied after it,
        kept its id past the forgetting, and every copy its client sent after the sim heard again was a
        "duplicate": the arm stayed where the halt left it (the grouped suite's run of 2026-11-30)."""
        with self.lock:
            self._applied[rid].clear()
            robot = self.world.robots[rid]
            moving = robot.moving
            if halt.reset:
                self._apply(rid, "reset", None)
            else:
                robot.halt()
        self.counters["staff_resets" if halt.reset else "owner_stops"] += 1
        if moving:
            self.report.event(EventKind.OWNER_STOP, rid, halt.reason, user=halt.user, severity="info")

    def _still_admitted(self, rid: str, name: str, cmd: Command) -> bool:
        """Ask the gate again as the command is applied: its sender may have lost the robot since it came."""
        if self._held:
            self._refuse_held(rid, name, cmd)
            return False
        refusal = self._gate_refusal(rid, cmd)
        if refusal:
            self.report.reject(
                rid,
                name,
                refusal,
                f"the gate refused {cmd.user}'s {name} command (epoch {cmd.epoch}) as it was applied",
                cmd.user,
                code="refused",
            )
            return False
        return True

    def _gate_refusal(self, rid: str, cmd: Command) -> str | None:
        """The gate's reason to refuse ``cmd`` now (None: admitted); a failing gate refuses, and says so."""
        try:
            return self.gate.admit(rid, cmd)
        except Exception as exc:
            log.exception("gate.admit failed")
            return f"gate error: {clip(str(exc))}"

    def _admit(self, key: str, cmd: Command) -> str | None:
        """Check a decoded command (robot, body, gate); its name when it may be applied."""
        self.counters["commands"] += 1
        try:
            parsed = keys.parse(key)
        except ValueError as exc:
            self.report.reject("", "?", "bad_key", clip(str(exc)), cmd.user)
            return None
        rid, name, sender = parsed.subject, parsed.leaf, parsed.user
        if rid not in self.world.robots:
            self.report.reject(
                rid,
                name,
                "unknown_robot",
                lambda: f"no robot {quote(rid, 64)} here; robots: {', '.join(self.world.robots)}",
                cmd.user,
            )
            return None
        if cmd.user != sender:
            # the key names the sender (a router's access control vouches for it); a payload claiming
            # someone else is a forgery or a bug, never a command
            self.report.reject(
                rid,
                name,
                "user_mismatch",
                f"the command names {quote(cmd.user, 64)} but was sent on {quote(sender, 64)}'s key",
                sender if is_valid_user(sender) else "",
            )
            return None
        mismatch = body_mismatch(name, cmd.body)
        if mismatch:
            self.report.reject(rid, name, "wrong_body", mismatch, cmd.user)
            return None
        if self._held:
            self._refuse_held(rid, name, cmd)
            return None
        refusal = self._gate_refusal(rid, cmd)
        if refusal:
            self.report.reject(
                rid,
                name,
                refusal,
                f"the gate refused {cmd.user}'s {name} command (epoch {cmd.epoch})",
                cmd.user,
                code="refused",
            )
            return None
        return name

    def _refuse_held(self, rid: str, name: str, cmd: Command) -> None:
        held = self._held
        with self._queued:
            self._stopped[rid] = cmd.user  # told again when the sim hears again (resume)
        self.report.reject(
            rid,
            name,
            "held",
            lambda: (
                f"the sim holds its robots ({held}); {cmd.user}'s {name} command is refused "
                "until it hears the fabric again"
            ),
            cmd.user,
            code="held",
        )

    def _execute(self, rid: str, name: str, cmd: Command) -> None:
        applied = self._applied[rid]
        try:
            with self.lock:
                if applied.seen(name, cmd):  # a copy of one applied already (a client riding out a pause)
                    self.counters["duplicates"] += 1
                    return
                clamp = self._apply(rid, name, cmd.body)
                applied.add(name, cmd)
        except CommandRejected as exc:
            self.report.reject(rid, name, exc.reason, str(exc), cmd.user)
            return
        self.counters["accepted"] += 1
        if clamp is not None:
            self.counters["clamped"] += 1
            self.report.event(
                EventKind.CLAMP,
                rid,
                "out_of_range" if name == "joints" else "over_limit",
                user=cmd.user,
                data={
                    "command": name,
                    "what": list(clamp.what),
                    "requested": list(clamp.requested),
                    "applied": list(clamp.applied),
                },
                limit=f"clamp:{rid}",
            )

    def _apply(self, rid: str, name: str, body: Any) -> Clamp | None:
        handler = self._handlers[rid].get(name)
        if handler is None:
            robot = self.world.robots[rid]
            raise CommandRejected(
                "unsupported",
                f"robot {rid} ({robot.desc.name}) does not take {name} commands; "
                f"it takes {', '.join(self._handlers[rid]) or 'none'}",
            )
        return handler(body)
