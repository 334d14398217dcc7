"""Robot handles: what a user holds to own, command and watch one robot of the world.

A class per robot kind (:class:`Arm`, :class:`Base`), chosen by the kind in the sim's world description
(:meth:`Robot.for_kind`); what all kinds share (ownership, commands, stop/reset, streams) is
:class:`Robot`. A handle reads the world's cache (:class:`~user_peer.latest.Latest`) and never keeps
state of its own, so two handles of one robot always agree.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Sequence

import numpy as np

from fabric import keys
from fabric.interfaces import (
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
    ServiceError,
    Stop,
    Twist,
    yaw_from_quaternion,
)
from fabric.reliable import resend_until
from user_peer import services
from user_peer.errors import NotOwner, Rejected, Timeout, Unreachable
from user_peer.streams import StreamIterator, Subscription

if TYPE_CHECKING:
    from user_peer.world import World

__all__ = ["Robot", "Arm", "Base", "robot_status"]


FIRST_STATE_WAIT_S = 1.0
"""How long a new robot handle waits for the robot's first state (a live sim sends it within a stream period)."""

COMMAND_ROUTE_WAIT_S = 0.5
"""How long a command waits for its sim's subscription to be known before it is put anyway."""

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
    sim too old to say which check refused), :class:`Rejected` for anything else."""
    data = ev.data if isinstance(ev.data, dict) else {}
    code = data.get("code")
    if code is None or code == OWNERSHIP_REFUSAL:
        return NotOwner(f"{robot} refused the command: {ev.reason}")
    detail = str(data.get("detail", ""))
    reason = f"{ev.reason}: {detail}" if detail and detail != ev.reason else ev.reason
    return Rejected(reason, robot=robot, command=str(data.get("command", "")), code=str(code))


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

    def send(self, command: str, body: Any, *, epoch: int | None = None) -> None:
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
        self.world.fabric.publish(key, Command(self.world.user, epoch, body, self.world.fabric.header(key)))

    def stop(self, *, confirm: bool = True, timeout: float = 3.0) -> bool:
        """Stop the robot where it is. Commands are dropped, not queued, when the network is congested, so
        with ``confirm`` the stop is sent again every 0.1 s until the robot's own stream shows it still
        (:func:`fabric.reliable.resend_until`); returns whether it was seen still within ``timeout``."""
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
            raise Timeout(f"no {stream} from {self.id} within {timeout or self.world.timeout:.1f} s (is the sim running?)")
        return msg


class Arm(Robot):
    """A robot arm: joint moves and Cartesian moves through a compute peer's IK."""

    kind = "arm"
    data_stream = "joints"

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

    def _reset_target(self) -> np.ndarray | None:
        """Where the sim's controller takes the joints on a reset: zero, within range (None: the world gave
        no limits)."""
        e = self.entry
        if not e.lower or len(e.lower) != len(e.upper):
            return None
        return np.clip(np.zeros(len(e.lower)), np.asarray(e.lower), np.asarray(e.upper))

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
            return self.world.compute_route.ask(
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
    data_stream = "pose"

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
        self._send_twist(v, omega)
        if (v or omega) and hold:
            epoch = self.record.epoch if self.record is not None else None
            self.world.twists.hold(self.id, lambda: self._send_twist(v, omega, epoch))
        else:
            self.world.twists.drop(self.id)

    def _send_twist(self, v: float, omega: float, epoch: int | None = None) -> None:
        key = keys.robot_cmd(self._w, self.id, "twist", self.world.user)
        self.send("twist", Twist(v, omega, self.world.fabric.header(key)), epoch=epoch)

    def drive(self, v: float, omega: float, duration: float, *, rate: float = 10.0) -> tuple[float, float, float] | None:
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
            services.map_request(self.world.fabric, "start", name=name, timeout=self.world.timeout, peer=self.world.compute_route.navigation_peer(),
                                 user=self.world.user)
        except ServiceError as exc:
            raise Unreachable(f"mapping for {self.id}: {exc.reason}") from None

    def build_map(self, *, name: str = "map", threshold: float = 0.65, timeout: float | None = None) -> OccupancyGrid:
        """The binary map a compute peer built from the scans so far: this user's own, kept and published as
        ``map/{user}.{name}`` (:func:`fabric.keys.user_map`; the class's map is the staff's). Plan on it with
        ``plan_to(..., map_name=keys.user_map(name, world.user))``."""
        try:
            return services.build_map(
                self.world.fabric, name=name, threshold=threshold, timeout=timeout or max(self.world.timeout, 10.0), peer=self.world.compute_route.navigation_peer(),
                user=self.world.user,
            )
        except ServiceError as exc:
            raise Unreachable(f"map for {self.id}: {exc.reason}") from None

    def plan_to(
        self, x: float | None = None, y: float | None = None, theta: float = 0.0, *, planner: str = "hybrid_astar",
        map_name: str = "map", timeout: float | None = None,
    ) -> Path:
        """A collision-free path from the robot's pose to (x, y, theta), or to the goal object without x, y, on
        ``map_name`` (default: the class's map)."""
        goal = None if x is None or y is None else (float(x), float(y), float(theta))
        try:
            return services.plan(
                self.world.fabric, self.id, goal, planner=planner, map_name=map_name, timeout=timeout or max(self.world.timeout, 15.0),
                peer=self.world.compute_route.navigation_peer(), user=self.world.user,
            )
        except ServiceError as exc:
            where = "the goal object" if goal is None else f"({goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.2f})"
            raise Unreachable(f"no path for {self.id} to {where}: {exc.reason}") from None

    def follow(self, path: Path, *, wait: bool = True, tol: float = 0.25, timeout: float = 120.0) -> tuple[float, float, float] | None:
        """Send ``path`` to the sim's follower; with ``wait``, block until the base stops near its end."""
        if len(path) == 0:
            raise ValueError("cannot follow an empty path")
        events_mark, data_mark = self.world.event_mark(), self.world.latest.mark()
        self.world.twists.drop(self.id)  # the sim's follower drives now
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
