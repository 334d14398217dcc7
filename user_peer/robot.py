"""Robot handles: what a user holds to own, command and watch one robot of the world.

A class per robot kind (:class:`~user_peer.arm.Arm`, :class:`~user_peer.mobile_base.Base`, each in its own
module), chosen by the kind in the sim's world description (:meth:`Robot.for_kind`); what all kinds share
(ownership, commands, stop/reset, streams) is :class:`Robot`. A handle
reads the world's cache (:class:`~user_peer.latest.Latest`) and never keeps state of its own, so two handles of
one robot always agree.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, ClassVar

import numpy as np

from fabric import keys
from fabric.interfaces import Command, Event, JointState, OwnershipRecord, Reset, Stop
from user_peer import services
from user_peer.errors import NotOwner, Paused, Rejected, Timeout
from user_peer.reliable import resend_until
from user_peer.streams import StreamIterator, Subscription

if TYPE_CHECKING:
    from user_peer.world import World

__all__ = ["Robot", "robot_status", "rejection_error"]


FIRST_STATE_WAIT_S = 1.0
"""How long a new robot handle waits for the robot's first state (a live sim sends it within a stream period)."""

COMMAND_ROUTE_WAIT_S = 0.5
"""How long a command waits for its sim's subscription to be known before it is put anyway."""

HELD = "held"
RESUMED = "resumed"  # the sim's word, once it hears again, that a hold stopped a command before it was done
"""The code of a sim's refusal while it holds its robots (cut off, or not yet sure of its link after a freeze):
raised as :class:`Paused`, ridden out by waited commands (:mod:`user_peer.pause`)."""

OWNERSHIP_REFUSAL = "refused"
"""The code (``Event.data["code"]``) of a sim's refusal by its ownership gate: raised as :class:`NotOwner`;
any other refusal (a bad frame, a wrong body, an unknown robot) is :class:`Rejected`."""


def _fmt_age(age: float | None) -> str:
    if age is None:
        return "no data yet"
    return f"{age * 1e3:.0f} ms ago" if age < 1.0 else f"{age:.1f} s ago"


def robot_status(world: "World", entry: services.RobotEntry) -> str:
    """One line about a robot: id, owner (you / someone / nobody), motion state, age of its latest data here.

    Reads only what the world already holds, so it may describe a robot nobody made a handle for
    (``repr(world)``) without subscribing to anything."""
    rec = world.ownership.record(entry.id)
    if rec is None:
        who = "no ownership record"
    elif rec.owner == world.user:
        who = "owned by you"
    elif rec.owner:
        who = f"owned by {rec.owner}"
    else:
        who = "free"
    if rec is not None and rec.queue:
        who += f", queue: {', '.join(rec.queue)}"
    state = f", {rec.state}" if rec is not None else ""
    stream = Robot.for_kind(entry.kind).data_stream
    age = world.latest.age(keys.robot_stream(world.name, entry.id, stream))
    return f"{entry.id} ({entry.type}): {who}{state}, {stream} {_fmt_age(age)}"


def rejection_error(robot: str, ev: Event) -> NotOwner | Rejected:
    """The error for a sim's refusal of a command: :class:`NotOwner` when its ownership gate refused it (or a
    sim too old to say which check refused), :class:`Paused` when the sim held its robots, :class:`Rejected` for
    anything else."""
    data = ev.data if isinstance(ev.data, dict) else {}
    code = data.get("code")
    if code is None or code == OWNERSHIP_REFUSAL:
        return NotOwner(f"{robot} refused the command: {ev.reason}")
    detail = str(data.get("detail", ""))
    reason = f"{ev.reason}: {detail}" if detail and detail != ev.reason else ev.reason
    kind = Paused if code in (HELD, RESUMED) else Rejected
    return kind(reason, robot=robot, command=str(data.get("command", "")), code=str(code))


def _still_after(msg: Any, seq: int) -> bool:
    """Whether ``msg`` (a robot's JointState or Pose) came after sequence number ``seq`` and shows it still."""
    if msg is None or msg.header.seq <= seq:
        return False
    if isinstance(msg, JointState):
        return float(np.max(np.abs(msg.dq), initial=0.0)) < 1e-6
    return float(np.linalg.norm(msg.linear)) < 1e-3 and float(np.linalg.norm(msg.angular)) < 1e-3


class Robot:
    """What every robot offers: ownership, stop, reset, its streams. Subclasses name their ``kind`` (the
    world description's word for it) and are found by it (:meth:`for_kind`)."""

    kind: ClassVar[str] = ""
    data_stream: ClassVar[str] = "joints"
    """The stream that shows where the robot is and whether it is still (its status line reports its age)."""
    _by_kind: ClassVar[dict[str, type["Robot"]]] = {}

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        if cls.kind:
            Robot._by_kind[cls.kind] = cls

    @staticmethod
    def for_kind(kind: str) -> type["Robot"]:
        """The handle class for a robot kind of the world description; a kind this client does not know
        gets the common :class:`Robot` (ownership, stop, reset, streams)."""
        from user_peer import arm, mobile_base  # noqa: F401  (the built-in kinds: each registers itself)

        return Robot._by_kind.get(kind, Robot)

    def __init__(self, world: "World", entry: services.RobotEntry) -> None:
        self.world = world
        self.id = entry.id
        self.type = entry.type
        self.entry = entry
        self._w = world.name
        if world.following.robot(self.id):  # a new handle: its first state, briefly (the latest was not kept before)
            key = keys.robot_stream(self._w, self.id, self.data_stream)
            world.latest.wait_for(lambda: world.latest.get(key), min(world.timeout, FIRST_STATE_WAIT_S))

    def status(self) -> str:
        """One line: id, owner (you / someone / nobody), motion state, age of the latest data here."""
        return robot_status(self.world, self.entry)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.status()}>"

    # ------------------------------------------------------------------ ownership (from the user's replica)

    @property
    def record(self) -> OwnershipRecord | None:
        """The robot's ownership record as the user's replica (:class:`~user_peer.ownership_link.OwnershipLink`)
        holds it; None when the world runs without ownership."""
        return self.world.ownership.record(self.id)

    @property
    def owner(self) -> str:
        """Who owns the robot ("" for nobody)."""
        rec = self.record
        return rec.owner if rec else ""

    @property
    def is_owner(self) -> bool:
        """Whether this user owns the robot."""
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
        """Give the robot up (the next in its queue owns it). The sim stops it: a base brakes, an arm holds."""
        self.world.twists.drop(self.id)
        self.world.ownership.release(self.id, timeout=self.world.timeout)

    def queue(self, *, timeout: float | None = None) -> int:
        """Take a place in the robot's queue without waiting for it (a UI's "queue for it"); returns the
        place (1: next), or 0 when the robot was granted at once (free, or still). :class:`NotOwner` when
        refused (the queue is full). The place and the grant show in :attr:`record` as they come."""
        return self.world.ownership.enqueue(self.id, timeout=timeout or self.world.timeout)

    @property
    def queue_place(self) -> int | None:
        """This user's place in the robot's queue (1: next), or None when not waiting for it."""
        rec = self.record
        if rec is None or self.world.user not in rec.queue:
            return None
        return rec.queue.index(self.world.user) + 1

    # ------------------------------------------------------------------ commands

    def send(self, command: str, body: Any, *, epoch: int | None = None) -> Command:
        """Send a command under this user's current epoch; :class:`NotOwner` if we know we do not own it
        (or, with ``epoch``, own it under another epoch: a repeat of a command given before it was lost).

        With no ownership record at all (a world run without ownership) the command goes out with
        epoch 0 and the sim, the authority, decides.
        """
        rec = self.record
        if rec is None:  # no replica yet (joined before the authority published): ask it, briefly
            rec = self.world.ownership.fetch(self.id, timeout=min(self.world.timeout, 1.0))
        if rec is not None and rec.owner != self.world.user:
            who = rec.owner or "nobody"
            raise NotOwner(f"{self.world.user} does not own {self.id} (owner: {who}); call request() first")
        if epoch is not None and rec is not None and rec.epoch != epoch:
            raise NotOwner(f"{self.id} changed hands since the command was given (epoch {epoch}, now {rec.epoch})")
        key = keys.robot_cmd(self._w, self.id, command, self.world.user)
        epoch = rec.epoch if rec is not None else 0
        # a sim that has just (re)started may not be known as a listener yet: its first command was lost
        # (the lab's clock-skew scenario, sim restarted: the sim counted 0 commands, the move timed out)
        self.world.fabric.wait_matching(key, COMMAND_ROUTE_WAIT_S)
        cmd = Command(self.world.user, epoch, body, self.world.fabric.header(key))
        self.world.fabric.publish(key, cmd)
        return cmd

    def resend(self, command: str, cmd: Command) -> None:
        """Send ``cmd`` (given as a ``command`` command) again, unchanged: the same id and epoch, so the sim applies
        it once whichever copy it takes (:mod:`sim_peer.serving.command_ids`); :class:`NotOwner` if the robot changed hands
        since (:mod:`user_peer.pause`)."""
        rec = self.record
        if rec is not None and (rec.owner != self.world.user or rec.epoch != cmd.epoch):
            raise NotOwner(
                f"{self.id} changed hands since the command was given (epoch {cmd.epoch}, now {rec.epoch}, "
                f"owner: {rec.owner or 'nobody'})"
            )
        self.world.fabric.publish(keys.robot_cmd(self._w, self.id, command, self.world.user), cmd)

    def stop(self, *, confirm: bool = True, timeout: float = 3.0) -> bool:
        """Stop the robot where it is. Commands are dropped, not queued, when the network is congested, so
        with ``confirm`` the stop is sent again every 0.1 s until the robot's own stream shows it still
        (:func:`user_peer.reliable.resend_until`); returns whether it was seen still within ``timeout``."""
        self.world.twists.drop(self.id)
        return self._control("stop", Stop, confirm, timeout)

    def reset(self, *, confirm: bool = True, timeout: float = 10.0) -> bool:
        """Send the robot back to its start (an arm at its speed limits); with ``confirm``, sent again until
        the robot is seen still (an arm: still at its start), as :meth:`stop`. Returns whether it was within ``timeout``."""
        self.world.twists.drop(self.id)
        return self._control("reset", Reset, confirm, timeout)

    def _control(self, command: str, body_type: type, confirm: bool, timeout: float) -> bool:
        key = keys.robot_cmd(self._w, self.id, command, self.world.user)
        stream = self.data_stream
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
        """Where a reset takes the robot, when the handle can check it got there (None: still is enough; a
        base is teleported home, still at once)."""
        return None

    def _check_rejected(self, since: int) -> None:
        """Raise the latest refusal of this user's commands to the robot since ``since`` (an event mark):
        :class:`NotOwner` from the ownership gate, :class:`Rejected` for anything else."""
        rej = self.world.rejections(self.id, since)
        if rej:
            raise rejection_error(self.id, rej[-1])

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
            raise Timeout(
                f"no {stream} from {self.id} within {timeout or self.world.timeout:.1f} s (is the sim running?)"
            )
        return msg
