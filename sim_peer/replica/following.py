"""What a sim hears of its shard's leader, and the world it restores from that when it takes over.

Every sim listens to the other sims' ``joints`` and ``pose`` streams: a primary hears a rival's term there, a
standby its leader's newest joints and poses, and its newest ownership records (``own/{object}``). A standby also
polls the leader's whole state on ``srv/state`` every ``poll_s`` and keeps the commands users send
(:class:`~sim_peer.replica.kept_commands.CommandBuffer`). At a take-over (:meth:`Follower.catch_up`) the world is put back
into the last snapshot, brought forward by the newer streams, its ownership records by the newer records
(:func:`ownership.carry.overlay`: a grant made after the snapshot keeps its epoch), its sequence numbers continued;
then the commands that came after the snapshot was asked for are applied again (:meth:`Follower.replay`).

The follower talks to the rest of the sim through what its constructor names (the fabric, the world it restores,
the election's view, the shard's robots, whom to tell what it heard), never the host. Its own lock guards what it
heard; the commands it keeps are guarded by the lock of what the host serves (``serving_lock``), passed in: a
command is either kept before a take-over takes the kept ones, or the new peer, already there, takes it itself.
The election changes under that lock too, so a polled snapshot is kept only if its source still leads then.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Protocol

from fabric import keys
from fabric.codec import DecodeError, decode
from fabric.interfaces import Command, JointState, OwnershipRecord, Pose, ServiceError, WorldState
from ownership.carry import changed_hands, overlay
from sim_peer.replica import election as el
from sim_peer.physics import capture
from sim_peer.replica.kept_commands import CommandBuffer

if TYPE_CHECKING:
    from fabric.gate import CommandGate
    from fabric.session import Fabric
    from sim_peer.physics.world import SimWorld
    from sim_peer.serving.peer import SimPeer

log = logging.getLogger("robofabric.sim")

__all__ = ["Follower", "Shard", "POLL_S", "REPLAY_MARGIN_S"]

POLL_S = 0.05
"""How often a standby asks the primary for the whole state (the streams fill in between)."""

REPLAY_MARGIN_S = 0.05
"""At a take-over, the commands heard from this long before the last snapshot was asked for are applied
again: a command reaches the standby and the primary by different routes, so one heard a little before
the query may have reached the primary after it answered. Applying one twice is harmless (a joint
target, a twist or an object pose is set to the same value; a path restarts from where the base is,
a few milliseconds along it)."""


DRAIN_QUIET_S = 0.06
"""At a take-over, the former leader's streams are waited for until none came for this long: samples that reached
this process before its token's loss may still wait in their subscription's thread (zenoh hands each
subscription's samples to a thread of its own), and a catch-up without the newest would start sim time a few
milliseconds before what other subscribers already saw (it once went 4 ms back). 30 ms was not enough once in a
whole `make test` (the eighth session's run 11: 4 ms back again), the subscription's thread starved longer."""
DRAIN_LIMIT_S = 0.3
"""The longest that wait lasts (a starved host): the take-over's budget is 1 s."""


class Shard(Protocol):
    """What the follower reads of this sim's shard (:class:`sim_peer.shards.directory.ShardDirectory`)."""

    @property
    def mine(self) -> frozenset[str]:
        """The robots this sim serves, or would serve at a take-over."""
        ...

    def about_mine(self, state: Any) -> bool:
        """Whether a ``srv/state`` answer is this shard's."""
        ...


class Follower:
    """The leader's last state as this sim knows it: its snapshot, its newest streams, the commands since.

    Its collaborators: ``fabric``; ``world`` (the world the host builds now: its robots and objects, restored at a
    take-over); ``election`` (the election's state now: this sim's role and leader); ``shard`` (:class:`Shard`);
    ``heard`` (a term heard from a sim, for the election) and ``seen_serving`` (a robot's stream from a sim, for the
    moves); ``serving`` (whether the host's peer serves now) and ``serving_lock`` (what the host serves, see the
    module); ``stopping``; ``clock`` (monotonic seconds); ``plant`` (a test-only defect, fabric/plant.py)."""

    def __init__(
        self,
        fabric: "Fabric",
        *,
        world: Callable[[], "SimWorld"],
        election: Callable[[], el.Election],
        shard: Shard,
        heard: Callable[[str, int], None],
        seen_serving: Callable[[str, str, int], None],
        serving: Callable[[], bool],
        serving_lock: threading.RLock,
        stopping: threading.Event,
        clock: Callable[[], float] = time.monotonic,
        snapshot: WorldState | None = None,
        poll_s: float = POLL_S,
        plant: str = "",
        announce: Callable[[str], None] = lambda line: None,
        kept: Callable[[], None] = lambda: None,
    ) -> None:
        self.fabric = fabric
        self._announce = announce  # the first state a standby holds of each leader is said: a take-over starts there
        self._kept = kept  # told after each snapshot kept (the role token shows a standby once it holds one)
        self._world, self._election, self._shard = world, election, shard
        self._heard, self._seen_serving = heard, seen_serving
        self._serving, self._serving_lock, self._stopping = serving, serving_lock, stopping
        self.clock = clock
        self.plant = plant
        self._lock = threading.Lock()  # what was heard: snapshot, joints, poses, records, heard_at, former
        self.poll_s = poll_s
        self.snapshot: WorldState | None = snapshot  # a primary that stepped down starts from its own last state
        self.snapshot_asked = clock()  # when the snapshot held was asked for: what came after is replayed
        self.waiting_s = poll_s
        """The wait between two polls the loop is in, or about to begin (no poll under way): a test that holds the
        polling (a longer ``poll_s``) waits until this is its own."""
        self.joints: dict[str, JointState] = {}
        self.poses: dict[str, Pose] = {}
        self.records: dict[str, OwnershipRecord] = {}  # the leader's newest record of each of its objects
        # robot commands and object poses of the last seconds (under serving_lock)
        self.commands = CommandBuffer(clock=clock)
        self.heard_at = float("-inf")  # when the leader's last joints or pose was kept (monotonic)
        self.former: str | None = None  # the leader a take-over is draining, whose streams are kept meanwhile
        self.followed: str | None = None  # the leader whose streams a standby kept last (see _from_leader)
        self._poller: threading.Thread | None = None

    def listen(self, standby: bool) -> None:
        """Subscribe to the other sims' streams, and as a standby to what users send."""
        f, w = self.fabric, self.fabric.world
        f.subscribe(keys.robot_stream_all(w, "joints"), self.on_joints, expected=JointState, remote_only=True)
        f.subscribe(keys.robot_stream_all(w, "pose"), self.on_pose, expected=Pose, remote_only=True)
        if standby:
            f.subscribe_raw(keys.robot_cmd_all(w), self.on_command_sample)
            f.subscribe(keys.own_all(w), self.on_record, expected=OwnershipRecord)
            for obj in self._world().objects:
                f.subscribe(keys.object_pose_all(w, obj), self.on_object, expected=Pose)

    def start_polling(self) -> None:
        self._poller = threading.Thread(target=self._poll, name="standby-poll", daemon=True)
        self._poller.start()

    def join(self, timeout: float) -> None:
        """Wait for the poll loop to see the host stopping."""
        if self._poller is not None:
            self._poller.join(timeout)

    def _poll(self) -> None:
        while True:
            self.waiting_s = self.poll_s
            if self._stopping.wait(self.waiting_s):
                return
            if self._election().role != el.STANDBY:
                return
            self._poll_once()

    def _poll_once(self) -> None:
        f = self.fabric
        asked = self.clock()
        try:
            replies = f.rpc.query(keys.srv(f.world, "state"), timeout=1.0, expected=WorldState, all_replies=True)
        except ServiceError:
            return
        best = max(
            (r.message for r in replies if self._shard.about_mine(r.message)),
            key=lambda m: m.header.term,
            default=None,
        )
        if best is None:
            return
        self._heard(best.header.source, best.header.term)
        first = kept = False
        with self._serving_lock:  # the election changes under it: no take-over between the look and the keep
            if best.header.source == self._election().leader:
                with self._lock:
                    held = self.snapshot
                    first, kept = held is None or held.header.source != best.header.source, True
                    self.snapshot, self.snapshot_asked = best, asked
        if not kept:
            return
        if first:
            self._announce(
                f"standby {f.peer_id}: holding the state of {best.header.source} (term {best.header.term}); "
                "a take-over starts from it"
            )
        self._kept()

    def holds_state(self) -> bool:
        """Whether a snapshot is held (its leader's, or its own as a primary that stepped down): a take-over from
        now on carries a world on instead of starting from the scene."""
        with self._lock:
            return self.snapshot is not None

    def on_joints(self, key: str, js: JointState) -> None:
        rid = keys.parse(key).subject
        self._seen_serving(rid, js.header.source, js.header.term)
        if rid not in self._shard.mine:
            return  # another shard's robot: its term is its shard's
        self._heard(js.header.source, js.header.term)
        if self._from_leader(js.header.source):
            with self._lock:
                self.joints[rid] = js
                self.heard_at = self.clock()

    def on_pose(self, key: str, p: Pose) -> None:
        rid = keys.parse(key).subject
        if rid not in self._shard.mine:
            return
        if self._from_leader(p.header.source):
            with self._lock:
                self.poses[rid] = p
                self.heard_at = self.clock()

    def _from_leader(self, source: str) -> bool:
        """Whether a stream sample from ``source`` is the followed leader's (or, from the moment the election made
        this sim primary until its take-over caught up, the leader's it followed)."""
        election = self._election()
        if election.role == el.STANDBY:
            if source == election.leader:
                self.followed = source
                return True
            return False
        # taking over: the election has made this sim primary, and its take-over thread has yet to start draining.
        # The streams of the leader it followed are kept from that moment on, not only from the drain's start: under
        # load that gap lasted long enough for the leader's last samples to be handled in it, and dropped (the
        # standby's first state then went 4 and 8 ms of sim time back, past a 60 ms drain)
        return source in (self.former, self.followed)

    def drain(self, former: str, quiet_s: float = DRAIN_QUIET_S, limit_s: float = DRAIN_LIMIT_S) -> float:
        """Keep ``former``'s streams until none came for ``quiet_s`` since the drain began (at most ``limit_s``),
        so that a take-over starts from the newest state that reached this process; the seconds waited. Call
        without the lock; the take-over ends the draining with :meth:`drained` once it caught up."""
        t0 = self.clock()
        with self._lock:
            self.former = former
        while (now := self.clock()) - t0 < limit_s and now - max(self.heard_at, t0) < quiet_s:
            time.sleep(min(quiet_s, 0.005))
        return self.clock() - t0

    def drained(self) -> None:
        with self._lock:
            self.former = self.followed = None

    def on_record(self, key: str, rec: OwnershipRecord) -> None:
        """Keep the leader's newest record of each object of this shard (epoch, then sequence number): the records it
        published after its last snapshot are carried over at a take-over."""
        world, election = self._world(), self._election()
        if rec.object not in world.robots and rec.object not in world.objects:
            return  # another shard's, or a made-up object: nothing to carry (and nothing to grow)
        if election.role == el.STANDBY and rec.header.source == election.leader:
            with self._lock:
                held = self.records.get(rec.object)
                if (
                    held is None
                    or held.header.source != rec.header.source
                    or (rec.epoch, rec.header.seq) >= (held.epoch, held.header.seq)
                ):
                    self.records[rec.object] = rec

    def keep(self, key: str, msg: Any, size: int = 0) -> None:
        """Keep one command (or object pose) heard now; a serving host's peer takes them itself."""
        with self._serving_lock:
            if self._serving():
                return  # serving: the peer takes commands itself (until it subscribes, they wait here)
            self.commands.keep(key, msg, size)

    def on_command_sample(self, sample: Any) -> None:
        try:
            payload = sample.payload.to_bytes()
            self.keep(str(sample.key_expr), decode(payload, Command), len(payload))
        except DecodeError:
            pass  # the authority reports it; a standby keeps only what it could apply

    def on_object(self, key: str, pose: Pose) -> None:
        self.keep(key, pose, 256)  # a pose is small and fixed in size (the codec caps its frame)

    def catch_up(self, state: WorldState) -> tuple[Any, Any]:
        """Put the host's world into ``state`` and the newer joints and poses its source streamed since, every robot
        brought to the newest time heard, the streams' sequence numbers continued (call with ``serving_lock`` held);
        the ownership records and users to restore the gate with: the snapshot's, with the newer records its
        source published since put over them (never an older epoch)."""
        with self._lock:
            joints, poses, records = dict(self.joints), dict(self.poses), list(self.records.values())
        f, world = self.fabric, self._world()
        capture.restore(world, state)
        src = state.header.source
        at = {rid: state.time for rid in world.robots}
        for rid, js in joints.items():
            if js.header.stamp >= state.time and js.header.source == src and rid in at:
                capture.overlay_joints(world, rid, js)
                at[rid] = js.header.stamp
        for rid, p in poses.items():
            if p.header.stamp >= state.time and p.header.source == src and rid in at:
                capture.overlay_pose(world, rid, p)
                at[rid] = p.header.stamp
        newest = max([state.time, *at.values()])
        capture.advance(world, {rid: newest - t for rid, t in at.items()})
        world.data.time = newest  # sim time goes on from the newest state heard, never back
        if self.plant == "reset":  # test-only defect (fabric/plant.py): robots start again from their spawn pose
            for robot in world.robots.values():
                robot.initialize(world.physics)
        seqs = {str(k): int(v) for k, v in state.seqs.items()}
        for rid, js in joints.items():
            k = keys.robot_joints(f.world, rid)
            seqs[k] = max(seqs.get(k, 0), js.header.seq + 1)
        for rid, p in poses.items():
            k = keys.robot_pose(f.world, rid)
            seqs[k] = max(seqs.get(k, 0), p.header.seq + 1)
        heard = [rec for rec in records if rec.header.source == src]
        for rec in heard:
            k = keys.own(f.world, rec.object)
            seqs[k] = max(seqs.get(k, 0), rec.header.seq + 1)
        f.seqs.carry_on(seqs)
        next_seqs = {r.object: int(state.seqs.get(keys.own(f.world, r.object), 0)) for r in heard}
        restored = overlay(state.records, state.users, heard, next_seqs)
        for rid in changed_hands(state.records, restored[0]):
            if (changed := world.robots.get(rid)) is not None:
                changed.halt()  # as its leader did when its owner went, after the snapshot
                log.info("%s: its owner changed after the snapshot taken over: stopped as its leader stopped it", rid)
        return restored

    def replay(self, peer: "SimPeer", gate: "CommandGate") -> None:
        """Apply again what users sent after the snapshot was asked for, in arrival order, before the new
        authority steps: the commands its restored ownership admits (the others the old authority
        refused, or would have; refusing them again would only repeat its events)."""
        with self._serving_lock:
            todo = self.commands.take_since(self.snapshot_asked - REPLAY_MARGIN_S)
        for key, msg in todo:
            try:
                if not isinstance(msg, Command):
                    peer.apply_object_pose(key, msg)
                elif gate.admit(keys.parse(key).subject, msg) is None:
                    peer.apply_command(key, msg)
            except Exception:
                log.exception("replaying %s at take-over failed", key)
