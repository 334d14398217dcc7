"""Replicated authority: a sim peer as a world's primary or as a standby that takes it over.

:class:`ReplicaHost` runs one fabric session in one role at a time, driven by the pure election core
(:mod:`sim_peer.election`):

- **primary**: a :class:`~sim_peer.peer.SimPeer` with its ownership gate, every message stamped with
  the authority epoch (``fabric.term``), and the whole world state served on ``rf/{world}/srv/state``
  (:class:`~fabric.interfaces.WorldState`). It listens to the joints streams: a higher term from
  another sim makes it step down. A publication gap longer than half the transport lease means it
  may have been frozen: it muzzles itself (publishes and answers nothing), asks ``srv/state`` who is authority now,
  and steps down if someone holds a higher term, else carries on.
- **standby**: builds the same scene, publishes nothing users act on (no streams, no records, no
  events; its ``srv/state`` answers with a refusal), polls ``srv/state``, keeps the newest joints and
  poses from the streams and the commands of the last seconds. When the leader's liveliness token
  goes and it is the lowest live standby, it takes over: term + 1, the world restored to the last
  state it saw (no reset), the commands that came after that state applied again (those the restored
  ownership admits), the ownership records and users carried over, sequence numbers continued, then
  streams, ``srv/world`` and the ownership queryables served again.

In a world served by several shards, the scene objects have one authority, the world's first sim. When it
goes and no standby of its shard has taken the objects over within ``adopt_after_s``, the serving primary
with the lowest id adopts them: it serves its robots and the objects again, one term up, with the objects
where it mirrored them (every sim moves them on the users' poses).

A robot moves between shards on ``srv/move/{sim}/by/{login}`` (:mod:`sim_peer.handoff`), the staff's key; a move
asked on ``srv/state``, which every login may ask, is refused. A source keeps what it handed out until its target
fetched it and serves it, or it takes it back; a target serves only what it fetched from the source.

A host that stepped down returns from :meth:`ReplicaHost.run`; the caller opens a fresh session and runs a
standby (``run_replicated``), so nothing the primary declared survives the change of role.
"""

from __future__ import annotations

import logging
import secrets
import threading
import time
from collections import deque
from dataclasses import replace
from typing import Any, Callable

from fabric import keys
from fabric.codec import DecodeError, decode, encode
from fabric.gate import CommandGate
from fabric.interfaces import Command, Event, EventKind, Header, JointState, Pose, ServiceError, WorldInfo, WorldState
from fabric.limits import clip
from fabric.session import Fabric
from sim_peer import election as el
from sim_peer import handoff as ho
from sim_peer import replica
from sim_peer.errors import WorldError
from sim_peer.peer import SimPeer
from sim_peer.registry import robot_class
from sim_peer.world import SimWorld
from robots.description import DescriptionError, SceneRobot

log = logging.getLogger("robofabric.sim")

__all__ = ["ReplicaHost", "run_replicated", "POLL_S", "REPLAY_MARGIN_S", "KEEP_COMMANDS_S", "SHARD_QUERY"]

POLL_S = 0.05
"""How often a standby asks the primary for the whole state (the streams fill in between)."""

REPLAY_MARGIN_S = 0.05
"""At a take-over, the commands heard from this long before the last snapshot was asked for are applied
again: a command reaches the standby and the primary by different routes, so one heard a little before
the query may have reached the primary after it answered. Applying one twice is harmless (a joint
target, a twist or an object pose is set to the same value; a path restarts from where the base is,
a few milliseconds along it)."""

SHARD_QUERY = "shard"
"""The ``Event.kind`` of a ``srv/state`` query asking a sim which robots it serves (its answer's ``data["robots"]``)."""

MOVE_ASK_S = 2.0
"""How long a sim waits for another's answer to a step of a move (a round trip; the other may be rebuilding)."""

KEEP_COMMANDS_S = 5.0
"""How long a standby keeps the commands it hears (far more than a poll period: a slow answer)."""

MAX_KEPT_COMMANDS = 4096
MAX_KEPT_BYTES = 16 * 1024 * 1024
"""Caps on what a standby keeps of those seconds (oldest dropped first): a client flooding commands
must not grow a standby's memory; a class's real commands in 5 s are far fewer."""

GateFactory = Callable[[Fabric, SimWorld, Any], Any]


class ReplicaHost:
    """One session of one sim peer in one role; ``run`` returns when stopped or after stepping down."""

    def __init__(
        self,
        fabric: Fabric,
        world: SimWorld,
        make_gate: GateFactory,
        *,
        standby: bool,
        rates: dict[str, float] | None = None,
        speed: float | None = 1.0,
        term: int = 0,
        leader: str = "",
        snapshot: WorldState | None = None,
        poll_s: float = POLL_S,
        freeze_gap: float | None = None,
        announce: Callable[[str], None] | None = None,
        objects: bool = True,
        rebuild: Callable[[list[SceneRobot]], SimWorld] | None = None,
        adopt_after_s: float | None = None,
    ) -> None:
        self.fabric = fabric
        # builds this sim's world again with other robots (the same scene and options): a robot moved in or out
        self.rebuild = rebuild
        # the scene objects' authority: the world's first sim (a shard joining a served world is not); a standby
        # learns it from its leader's state at a take-over (a primary that is not describes no objects there)
        self.objects = objects
        self.mine = frozenset(world.robots)  # this shard: the robots this sim serves, or would serve at a take-over
        self.shards: dict[str, frozenset[str]] = {}  # live sim -> the robots it serves (from srv/state, asked)
        self.world = world
        self.make_gate = make_gate
        self.rates = rates
        self.speed = speed
        self.poll_s = poll_s
        self.announce = announce or (lambda text: log.info("%s", text))
        me = fabric.peer_id
        if standby:
            self.election = el.Election(me, el.STANDBY, term, leader)
        else:
            self.election = el.start(me, standby=False, term=term + 1)
        self.peer: SimPeer | None = None
        self.gate: CommandGate | None = None
        self.snapshot: WorldState | None = snapshot  # a primary that stepped down starts from its own last state
        self.joints: dict[str, JointState] = {}
        self.poses: dict[str, Pose] = {}
        # (local arrival, key, message) of robot commands and object poses, and when the snapshot we hold
        # was asked for: what came after it is applied again at a take-over (a joint target sent in the
        # last poll period before the primary died is otherwise lost, and the arm stops short)
        self.commands: deque[tuple[float, str, Any, int]] = deque()  # (arrival, key, message, payload bytes)
        self._kept_bytes = 0
        self.snapshot_asked = time.monotonic()
        self.live: set[str] = set()
        self._gone_at: dict[str, float] = {}  # sim id -> when its token went (monotonic): was it there when we froze?
        self._settled = False  # the first complete view of the live sims is in (open)
        self._learning = self._learn_again = False  # a shard query under way, and another wanted after it
        self.takeovers: list[dict[str, Any]] = []
        self.last_state: WorldState | None = None
        self._lock = threading.RLock()
        self._closed = False
        self._stepped_down = threading.Event()
        self._stop = threading.Event()
        self._poller: threading.Thread | None = None
        self._taking_over: threading.Thread | None = None
        # half the transport lease: a freeze long enough for the others to drop our token (a lease) is
        # always caught, with margin; a false alarm (a starved process) costs one query, muzzled
        self.freeze_gap = freeze_gap if freeze_gap is not None else fabric.config.lease_ms / 2000.0
        # after a sim leaves, how long a shard waits for the objects' standby (a take-over takes well under a
        # lease) before asking whether the scene objects still have an authority
        self.adopt_after_s = adopt_after_s if adopt_after_s is not None else 2.0 * fabric.config.lease_ms / 1000.0 + 1.0
        self._adopting = self._adopt_again = False
        # moving robots: this sim's login (it asks other sims in its own name), what it handed out and keeps until
        # the target serves it or it takes it back, and the timers that take back what no target fetched
        self.login = fabric.config.identity() or fabric.peer_id
        self._handed_out: dict[str, ho.HandedOut] = {}
        self._timers: list[threading.Timer] = []

    # ------------------------------------------------------------------ lifecycle

    @property
    def role(self) -> str:
        return self.election.role

    def open(self, duration: float | None = None) -> "ReplicaHost":
        f, w = self.fabric, self.fabric.world
        self._duration = duration
        f.serve(keys.srv(w, "state"), self._on_state_query)
        f.serve(keys.srv_move_served(w, f.peer_id), self._on_move_query, expected=Event)
        if self.role == el.PRIMARY:
            self._serve(None)  # the world first: nothing below may delay a primary's streams and services
        # other sims' streams only: a primary hears a rival's term there, a standby its leader's state
        f.subscribe(keys.robot_stream_all(w, "joints"), self._on_joints, expected=JointState, remote_only=True)
        f.subscribe(keys.robot_stream_all(w, "pose"), self._on_pose, expected=Pose, remote_only=True)
        if self.role != el.PRIMARY:
            f.subscribe_raw(keys.robot_cmd_all(w), self._on_command_sample)
            for obj in self.world.objects:
                f.subscribe(keys.object_pose_all(w, obj), self._on_object, expected=Pose)
        # first a complete view of the live sims, then changes: the election reads a leader missing from a
        # view as gone, so the view must not be a history still arriving. The watch comes first (what it
        # hears meanwhile is kept, but decides nothing until the view is settled), then a liveliness query
        f.watch_peers(self._on_sim, kind="sim")
        try:
            initial = {pid for _, pid in f.live_peers("sim", timeout=2.0)}
        except Exception:
            initial = set()
        with self._lock:
            self.live |= initial | {f.peer_id}
        if len(self.live) > 1:
            self._learn_shards()
        self._await_leader(self.election.leader)
        with self._lock:
            self._settled = True
            live = frozenset(self.live)
        self._step(el.Peers(self._shard_view(live)))
        if self.role != el.PRIMARY:
            self._poller = threading.Thread(target=self._poll, name="standby-poll", daemon=True)
            self._poller.start()
            self.announce(f"standby {f.peer_id}: following {self.election.leader or 'the primary'} (term {self.election.term})")
        return self

    def run(self, stop: threading.Event, duration: float | None = None) -> str:
        """Serve or follow until ``stop`` or a step-down; returns the role it ended in."""
        self.open(duration)
        try:
            while not stop.is_set() and not self._stepped_down.is_set():
                stop.wait(0.1)
                with self._lock:  # a robot moving in or out rebuilds under the lock: its closed peer is not the end
                    if self.peer is not None and self.peer.finished:
                        break  # --duration reached
        finally:
            self.close()
        return self.role

    def __enter__(self) -> "ReplicaHost":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop following or serving; idempotent. The fabric stays open (its maker closes it)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._stop.set()
        for timer in self._timers:
            timer.cancel()
        # a take-over under way finishes first: closed meanwhile, it raised from its thread and could
        # start a peer after close() had looked for one
        taking = self._taking_over
        if taking is not None and taking is not threading.current_thread():
            taking.join(10.0)
        if self.peer is not None and self.role == el.STANDBY:  # stepped down: keep what we had, in case
            try:
                self.last_state = self._on_state_query("", None, force=True)
            except Exception:
                log.debug("no state kept at step-down", exc_info=True)
        if self._poller is not None:
            self._poller.join(2.0)
        if self.peer is not None:
            self.peer.close()
        if self.gate is not None:
            self.gate.close()

    # ------------------------------------------------------------------ primary

    def _serve(self, state: WorldState | None) -> None:
        """Serve the world as its authority with the current term, from ``state`` when taking over."""
        f = self.fabric
        restored = None
        with self._lock:
            if state is not None:
                replica.restore(self.world, state)
                src = self._followed(state)
                at = {rid: state.time for rid in self.world.robots}
                for rid, js in self.joints.items():
                    if js.header.stamp >= state.time and js.header.source == src and rid in at:
                        replica.overlay_joints(self.world, rid, js)
                        at[rid] = js.header.stamp
                for rid, p in self.poses.items():
                    if p.header.stamp >= state.time and p.header.source == src and rid in at:
                        replica.overlay_pose(self.world, rid, p)
                        at[rid] = p.header.stamp
                newest = max([state.time, *at.values()])
                replica.advance(self.world, {rid: newest - t for rid, t in at.items()})
                self.world.data.time = newest  # sim time goes on from the newest state heard, never back
                seqs = {str(k): int(v) for k, v in state.seqs.items()}
                for d in (self.joints, self.poses):
                    for rid, m in d.items():
                        k = keys.robot_joints(f.world, rid) if d is self.joints else keys.robot_pose(f.world, rid)
                        seqs[k] = max(seqs.get(k, 0), m.header.seq + 1)
                f.continue_sequences(seqs)
                restored = (state.records, state.users)
            if state is not None and self.world.objects:
                self.objects = bool(state.objects)  # the shard we take over was the objects' authority, or not
            f.assume_term(self.election.term, self._scopes())
        f.watch_freeze(self.freeze_gap, self._on_freeze)
        if self.objects:
            self.gate = self.make_gate(f, self.world, restored)
        else:
            self.gate = self.make_gate(f, self.world, restored, objects=False)
        self.peer = SimPeer(f, self.world, gate=self.gate, rates=self.rates, speed=self.speed, objects=self.objects)
        if state is not None:
            self._replay(self.peer)
        self.peer.start(self._duration)

    def _replay(self, peer: SimPeer) -> None:
        """Apply again what users sent after the snapshot was asked for, in arrival order, before the new
        authority steps: the commands its restored ownership admits (the others the old authority
        refused, or would have; refusing them again would only repeat its events)."""
        with self._lock:
            since = self.snapshot_asked - REPLAY_MARGIN_S
            todo = [(key, msg) for t, key, msg, _ in self.commands if t >= since]
            self.commands.clear()
            self._kept_bytes = 0
        for key, msg in todo:
            try:
                if not isinstance(msg, Command):
                    peer.apply_object_pose(key, msg)
                elif self.gate.admit(keys.parse(key).subject, msg) is None:
                    peer.apply_command(key, msg)
            except Exception:
                log.exception("replaying %s at take-over failed", key)

    def _scopes(self) -> tuple[str, ...]:
        """What this sim is the authority of: its robots, and the scene objects when it is their authority."""
        return tuple(self.world.robots) + (tuple(self.world.objects) if self.objects else ())

    def _on_state_query(self, key: str, request: Any, *, force: bool = False) -> WorldState | Event:
        if isinstance(request, Event) and request.kind == SHARD_QUERY:
            # which shard this sim belongs to, primary or standby: its robots (an election counts the sims of its shard)
            return Event(kind=SHARD_QUERY, reason=self.role, object="", data={"robots": sorted(self.mine)},
                         header=Header(wall_ns=time.time_ns(), source=self.fabric.peer_id))
        if isinstance(request, Event) and request.kind in ho.STEPS:
            # every login may ask srv/state: a move asked here is refused, whoever asks (moves: srv/move, the staff's)
            raise self._move_refused(request, "", f"moves are for the instructor and sim logins: srv/state, which every login "
                                                  f"may ask, moves nothing (robofabric own move asks srv/move/SIM/by/LOGIN)")
        peer = self.peer
        if peer is None or (self.role != el.PRIMARY and not force):
            raise ServiceError(f"{self.fabric.peer_id} is a standby (term {self.election.term})")
        records, users = self.gate.export_state()
        with peer.lock:
            t, steps, robots, objects = replica.capture(self.world)
        if not self.objects:
            objects = ()  # the objects' authority is another shard: its standby must not become it
        seqs = self.fabric.sequences(keys.world_root(self.fabric.world))
        return WorldState(t, steps, robots, objects, tuple(records), dict(users), seqs,
                          header=self.fabric.header(keys.srv(self.fabric.world, "state"), stamp=t))

    # ------------------------------------------------------------------ moving a robot between sims

    def _on_move_query(self, key: str, request: Any) -> Event | None:
        """One step of a move (:mod:`sim_peer.handoff`) asked on ``srv/move/{me}/by/{login}``: the staff's key (a
        class's router lets the instructor and sim logins ask there, each in its own name). A refusal is answered
        with its reason, counted (``moves_refused``), logged and published on ``event/move``."""
        try:
            asker = keys.asker(keys.parse(key))
        except ValueError:
            asker = ""
        if not isinstance(request, Event) or request.kind not in ho.STEPS:
            raise self._move_refused(request, asker, f"a move's step is an Event of kind {', '.join(ho.STEPS)}")
        try:
            return self._move_step(request, asker)
        except (ServiceError, ho.MoveError, WorldError, DescriptionError, ValueError) as exc:
            raise self._move_refused(request, asker, exc.reason if isinstance(exc, ServiceError) else str(exc)) from None

    def _move_refused(self, request: Any, asker: str, reason: str) -> ServiceError:
        """Count, log and publish a refused step of a move; the error its asker gets."""
        f = self.fabric
        f.counters["moves_refused"] += 1
        kind = request.kind if isinstance(request, Event) and request.kind in ho.STEPS else "other"
        robot = request.object if isinstance(request, Event) else ""
        ev = Event(kind=EventKind.MOVE_REFUSED, reason=clip(reason, 400), object=clip(str(robot), 64), user=clip(asker, 64),
                   severity="warning", data={"step": kind}, header=f.header("event"))
        if self.role == el.PRIMARY:
            f.emit(ev, "move", limit=f"move_refused:{kind}")  # kind: a fixed word, never client text
        else:
            log.warning("move refused (%s, by %s): %s", kind, asker or "?", clip(reason, 400))
        return ServiceError(reason)

    def _move_step(self, request: Event, asker: str) -> Event | None:
        me, d = self.fabric.peer_id, request.data if isinstance(request.data, dict) else {}
        rid = keys.validate_id(request.object, what="robot id")
        to, source, move_id = str(d.get("to", "")), str(d.get("from", "")), str(d.get("move", ""))
        term = d.get("term", 0)
        if not isinstance(term, int) or isinstance(term, bool):
            raise ho.MoveError(f"a move's term is an integer, got {clip(repr(term), 40)}")
        if request.kind == ho.MOVE_CHECK:
            with self._lock:
                self._check_mover()
                return ho.step(ho.MOVE_CHECK, rid, to=to, source=me, term=self.election.term, asker=me)
        if request.kind == ho.MOVE_OUT:
            return self._move_out(rid, keys.validate_id(to, what="target sim"), term, asker)
        if request.kind == ho.MOVE_PREPARE:
            return self._prepare(rid, source, str(d.get("type", "")))
        if request.kind == ho.MOVE_FETCH:
            return self._fetch(rid, to, term, move_id, bool(d.get("decline", False)))
        if to != me:
            raise ho.MoveError(f"this is sim {me}: a move_in to sim {to} is not for it")
        if source == me:
            return self._take_back(rid, move_id, asker)
        return self._move_in(rid, keys.validate_id(source, what="source sim"), term, move_id, asker)

    def _check_mover(self) -> None:
        """Raise unless this sim may move robots in or out now (call with the lock held)."""
        me = self.fabric.peer_id
        if self.role != el.PRIMARY or self.peer is None:
            raise ServiceError(f"sim {me} is not serving (a standby, or taking over)")
        if self.rebuild is None:
            raise ServiceError(f"sim {me} cannot rebuild its world (a sim of robofabric sim moves robots)")
        standbys = sorted(p for p, robots in self.shards.items() if p != me and p in self.live and robots & self.mine)
        if standbys:
            raise ServiceError(f"sim {me} has standbys ({', '.join(standbys)}): moving a robot of a replicated shard is not supported")

    def _ask_sim(self, sim: str, request: Event) -> Event:
        """Ask another sim one step of a move in this sim's login (a sim login may ask ``srv/move``)."""
        return ho.ask(self.fabric, sim, self.login, request, MOVE_ASK_S)

    def _move_out(self, rid: str, to: str, term: int, asker: str) -> Event:
        """The source's step: the target's word first (it would take the robot, and its term), then the robot
        handed out and kept for it (:meth:`_hand_out`). A target that is not there or would not take it, or a term
        that is not the election's, changes nothing."""
        me = self.fabric.peer_id
        with self._lock:
            self._check_mover()
            if rid not in self.world.robots:
                raise ho.MoveError(f"sim {me} does not serve robot {rid}")
            if rid in self._handed_out:
                raise ho.MoveError(f"robot {rid} is being moved already")
            if len(self.world.robots) < 2:
                raise ho.MoveError(f"robot {rid} is sim {me}'s last robot: stop that sim and start {rid} on another instead")
            if to == me or to not in self.live:
                raise ho.MoveError(f"sim {to} is not another live sim of world {self.fabric.world!r}: {rid} stays with sim {me}")
            my_term, rtype = self.election.term, self.world.robots[rid].desc.name
        # outside the lock: the target's answer takes a round trip, and this sim keeps serving meanwhile
        answer = self._ask_sim(to, ho.step(ho.MOVE_PREPARE, rid, to=to, source=me, term=term, rtype=rtype, asker=me))
        theirs = answer.data.get("term") if isinstance(answer.data, dict) else None
        if not isinstance(theirs, int) or isinstance(theirs, bool):
            raise ho.MoveError(f"sim {to} did not say its term")
        want = ho.move_term(my_term, theirs)
        if term != want:
            raise ho.MoveError(f"move term {term} is not the one the election gives ({want}: above sim {me}'s term {my_term} "
                               f"and sim {to}'s {theirs}): ask again")
        with self._lock:
            self._check_mover()
            if self.election.term != my_term or rid not in self.world.robots or rid in self._handed_out:
                raise ho.MoveError(f"sim {me} changed while sim {to} was asked: ask again")
            return self._hand_out(rid, to, term, asker)

    def _prepare(self, rid: str, source: str, rtype: str) -> Event:
        """The target's word before a source lets a robot go: it serves, does not serve ``rid``, and has its type
        installed (a NAME, found among this machine's robots: :func:`robots.installed`); its answer gives its term."""
        import robots

        me = self.fabric.peer_id
        with self._lock:
            self._check_mover()
            if rid in self.world.robots:
                raise ho.MoveError(f"sim {me} already serves {rid}")
            term = self.election.term
        robot_class(robots.installed(rtype))  # the operator's plug-in, by name; a path is refused, never read
        return ho.step(ho.MOVE_PREPARE, rid, to=me, source=source, term=term, asker=me)

    def _fetch(self, rid: str, to: str, term: int, move_id: str, decline: bool) -> Event:
        """The source's answer to its target: the robot it handed out to that sim in that move at that term
        (``decline``: the target gives it back, having served nothing of it)."""
        me = self.fabric.peer_id
        with self._lock:
            kept = self._handed_out.get(rid)
            why = ho.fetch_refusal(kept, rid, to, term, move_id)
            if why:
                raise ho.MoveError(why)
            assert kept is not None
            self._handed_out[rid] = replace(kept, fetched=not decline)
        if decline:
            return ho.step(ho.MOVE_FETCH, rid, to=to, source=me, term=term, move_id=move_id, asker=me, decline=True)
        return ho.to_event(ho.MOVE_FETCH, rid, to, kept.handoff, term=term, source=me)

    def _stop_serving(self) -> tuple[WorldState, dict[str, SceneRobot]]:
        """Stop the peer and the gate (call with the lock held); the world's state as they left it."""
        f, peer = self.fabric, self.peer
        f.watch_freeze(None, None)  # a rebuild is not a freeze
        peer.close()
        records, users = self.gate.export_state()
        self.gate.close()
        with peer.lock:
            t, steps, robots, objects = replica.capture(self.world)
        state = WorldState(t, steps, robots, objects if self.objects else (), tuple(records), dict(users), {},
                           header=Header(wall_ns=time.time_ns(), source=f.peer_id))
        self.peer = self.gate = None
        return state, dict(self.world.placements)

    def _serve_rebuilt(self, world: SimWorld, state: WorldState, term: int, seqs: dict[str, int]) -> None:
        """Serve ``world`` (built with the robots it is to serve), restored to ``state``, under ``term`` (the
        take-over path)."""
        self.world = world
        self.mine = frozenset(self.world.robots)
        self.election = replace(self.election, term=term)
        self.fabric.continue_sequences(seqs)
        self._serve(replace(state, header=replace(state.header, term=term)))
        self._learn_shards_soon()

    def _serve_again(self, placements: dict[str, SceneRobot], state: WorldState, term: int) -> None:
        """After a rebuild that failed half-way: whatever started is closed and the old robots served again, at the
        term the failed rebuild took (never lower: anything it published was stamped with it)."""
        for part in (self.peer, self.gate):
            if part is not None:
                try:
                    part.close()
                except Exception:
                    log.debug("closing after a failed rebuild", exc_info=True)
        self.peer = self.gate = None
        self._serve_rebuilt(self.rebuild(list(placements.values())), state, term, {})

    def _hand_out(self, rid: str, to: str, term: int, asker: str) -> Event:
        """Stop serving ``rid`` and keep it for ``to`` (call with the lock held). The world without it is built
        before anything stops: a world that cannot be built changes nothing."""
        t0, me = time.monotonic(), self.fabric.peer_id
        placements = dict(self.world.placements)
        rest_world = self.rebuild([p for r, p in placements.items() if r != rid])
        rtype = self.world.robots[rid].desc.name
        state, placements = self._stop_serving()
        robot = next(r for r in state.robots if r.id == rid)
        record = next((r for r in state.records if r.object == rid), None)
        seqs = self.fabric.sequences(keys.world_root(self.fabric.world) + f"/robot/{rid}/")
        handoff = ho.Handoff(robot, replace(placements[rid], type=rtype), record, ho.named_users(state.users, record), seqs, term, me)
        rest = replace(state, robots=tuple(r for r in state.robots if r.id != rid), records=ho.merge_records(state.records, drop=rid))
        try:
            ho.from_event(decode(encode(ho.to_event(ho.MOVE_FETCH, rid, to, handoff, term=term, source=me)), Event))  # it can travel
            self._serve_rebuilt(rest_world, rest, term, {})
        except Exception as exc:
            log.exception("handing %s out failed", rid)
            self._serve_again(placements, state, self.election.term)
            raise ServiceError(f"sim {me} could not hand {rid} out ({exc}); it keeps serving it") from None
        move_id = secrets.token_hex(8)
        self._handed_out[rid] = ho.HandedOut(handoff, to, move_id, placement=placements[rid], at=time.monotonic())
        timer = threading.Timer(ho.RETURN_AFTER_S, self._return_unclaimed, args=(rid, move_id))
        timer.daemon = True
        timer.start()
        self._timers.append(timer)
        self.announce(f"sim {me}: handed {rid} out to {to} (term {term}) in {(time.monotonic() - t0) * 1000:.0f} ms"
                      + (f", asked by {asker}" if asker else ""))
        return ho.step(ho.MOVE_OUT, rid, to=to, source=me, term=term, move_id=move_id, asker=me)

    def _move_in(self, rid: str, source: str, term: int, move_id: str, asker: str) -> Event:
        """The target's step: the robot fetched from its source (never taken from the query), checked, served. A
        refusal after the fetch gives it back to the source, which may then serve it again."""
        import robots

        me = self.fabric.peer_id
        with self._lock:
            self._check_mover()
            if rid in self.world.robots:
                raise ho.MoveError(f"sim {me} already serves {rid}")
            if term < self.election.term:
                raise ho.MoveError(f"move term {term} is below sim {me}'s term {self.election.term}: ask again")
        handoff = ho.from_event(self._ask_sim(source, ho.step(ho.MOVE_FETCH, rid, to=me, source=source, term=term,
                                                              move_id=move_id, asker=me)))
        try:
            ho.check_handoff(handoff, rid, source, term)
            desc = robots.installed(handoff.placement.type)  # a name: the operator's installed robot, never a path
            robot_class(desc)
            with self._lock:
                self._check_mover()
                if rid in self.world.robots or term < self.election.term:
                    raise ho.MoveError(f"sim {me} changed while sim {source} was asked: ask again")
                self._take_in(handoff, replace(handoff.placement, type=str(desc.directory / "robot.toml")), term, asker)
        except BaseException:
            self._give_back(source, rid, term, move_id)
            raise
        return ho.step(ho.MOVE_IN, rid, to=me, source=source, term=term, move_id=move_id, asker=me)

    def _give_back(self, source: str, rid: str, term: int, move_id: str) -> None:
        try:
            self._ask_sim(source, ho.step(ho.MOVE_FETCH, rid, to=self.fabric.peer_id, source=source, term=term,
                                          move_id=move_id, asker=self.fabric.peer_id, decline=True))
        except ho.MoveError as exc:
            log.warning("could not give %s back to sim %s: %s", rid, source, exc)

    def _take_in(self, handoff: ho.Handoff, placement: SceneRobot, term: int, asker: str = "") -> None:
        """Serve ``handoff``'s robot placed at ``placement`` with this sim's own (call with the lock held). The
        new world is built before anything stops; a failure after the stop serves the old world again."""
        t0, me = time.monotonic(), self.fabric.peer_id
        rid = handoff.state.id
        world = self.rebuild([*self.world.placements.values(), placement])
        state, placements = self._stop_serving()
        full = replace(state, robots=(*state.robots, handoff.state), records=ho.merge_records(state.records, add=handoff.record),
                       users=ho.merge_users(state.users, handoff.users))
        try:
            self._serve_rebuilt(world, full, term, dict(handoff.seqs))
        except Exception as exc:
            log.exception("taking %s in failed", rid)
            self._serve_again(placements, state, self.election.term)
            raise ServiceError(f"sim {me} could not serve {rid} ({exc}); it serves what it served") from None
        self.announce(f"sim {me}: took {rid} in from {handoff.source or 'another sim'} (term {term}) in "
                      f"{(time.monotonic() - t0) * 1000:.0f} ms" + (f", asked by {asker}" if asker else ""))

    def _take_back(self, rid: str, move_id: str | None, asker: str) -> Event:
        """The source serves a robot it handed out again, as it kept it (``move_id`` None: its own timer)."""
        me = self.fabric.peer_id
        with self._lock:
            self._check_mover()
            kept = self._handed_out.get(rid)
            why = ho.take_back_refusal(kept, rid, move_id, kept is not None and kept.to in self.live)
            if why:
                raise ho.MoveError(why)
            assert kept is not None
            if rid in self.world.robots:
                raise ho.MoveError(f"sim {me} serves {rid} already")
            self._take_in(kept.handoff, kept.placement, self.election.term, asker or "this sim")
            del self._handed_out[rid]
        return ho.step(ho.MOVE_IN, rid, to=me, source=me, term=self.election.term, move_id=kept.move, asker=me)

    def _return_unclaimed(self, rid: str, move_id: str) -> None:
        """A robot handed out that no target fetched within :data:`~sim_peer.handoff.RETURN_AFTER_S` (the tool
        died between its steps) is served here again."""
        with self._lock:
            kept = self._handed_out.get(rid)
            if self._closed or kept is None or kept.move != move_id or kept.fetched:
                return
        try:
            self._take_back(rid, None, "")
        except (ServiceError, ho.MoveError) as exc:
            log.warning("could not serve %s again after its move: %s", rid, exc)
            return
        self.announce(f"sim {self.fabric.peer_id}: no sim took {rid} within {ho.RETURN_AFTER_S:.0f} s; serving it again")

    def _drop_handed_out(self, rid: str, sim: str, term: int) -> None:
        """``sim`` serves ``rid`` at ``term`` (its joints came): what this sim kept of it is no longer to be taken back."""
        with self._lock:
            kept = self._handed_out.get(rid)
            if kept is not None and kept.to == sim and term >= kept.handoff.term:
                del self._handed_out[rid]

    # ------------------------------------------------------------------ the scene objects after their sim

    def _adopt_soon(self) -> None:
        """A sim left: after ``adopt_after_s``, see whether the scene objects went with it (one thread at a time)."""
        with self._lock:
            if self.objects or self._closed:
                return
            self._adopt_again = True
            if self._adopting:
                return
            self._adopting = True

        def run() -> None:
            while not self._stop.wait(self.adopt_after_s):
                with self._lock:
                    again, self._adopt_again = self._adopt_again, False
                    if not again or self.objects or self._closed:
                        self._adopting = False
                        return
                try:
                    self._adopt_if_orphaned()
                except Exception:  # a closing session; the next departure asks again
                    log.debug("adopting the scene objects failed", exc_info=True)
            with self._lock:
                self._adopting = False

        threading.Thread(target=run, name="sim-adopt-objects", daemon=True).start()

    def _adopt_if_orphaned(self) -> bool:
        """Serve the scene objects when no live sim describes them and this is the lowest-id sim that serves a
        part of the world (every shard asks the same union, so one adopts); True when this one did."""
        f, me = self.fabric, self.fabric.peer_id
        try:
            replies = f.query(keys.srv(f.world, "world"), timeout=2.0, expected=WorldInfo, all_replies=True)
        except ServiceError:
            return False
        parts = {r.source: r.message for r in replies if r.source}
        if not self.world.objects or any(p.objects for p in parts.values()) or me not in parts or min(parts) != me:
            return False
        with self._lock:
            if self.role != el.PRIMARY or self.peer is None or self.objects or self._closed:
                return False
            t0 = time.monotonic()
            self.objects = True  # before the capture: the state carries the objects where this sim mirrored them
            state, _ = self._stop_serving()
            term = self.election.term + 1
            self.election = replace(self.election, term=term)
            self._serve(replace(state, header=replace(state.header, term=term)))
        self.announce(f"sim {me}: no sim serves the scene objects any more; serving {', '.join(self.world.objects)} "
                      f"with my robots (term {term}) in {(time.monotonic() - t0) * 1000:.0f} ms")
        return True

    def _on_freeze(self, gap: float) -> None:
        """Frozen for ``gap`` s: muzzled until it is known whether another sim may hold the world now.

        With no other sim alive when the freeze began (nothing could have taken over), publish again at
        once. Otherwise, after a gap longer than the lease (the others dropped our token, and our session
        may not even know yet that its link died), listen muzzled for a lease: a new authority's streams
        reach us once the session is back, and hearing its higher term steps us down before anything goes
        out; then ask ``srv/state``, step down if a higher term answers, carry on otherwise."""
        f = self.fabric
        lease = f.config.lease_ms / 1000.0
        began = time.monotonic() - gap
        with self._lock:
            rivals = {p for p in self.live | {p for p, t in self._gone_at.items() if t >= began} if p != f.peer_id and self._same_shard(p)}
        if not rivals:
            f.unmuzzle()
            self.announce(f"sim {f.peer_id}: paused {gap:.1f} s with no other sim in the world; publishing again (term {f.term})")
            return
        if gap > lease:
            self._stop.wait(lease + 0.5)
        deadline = time.monotonic() + max(30.0, 10 * self.freeze_gap)
        while time.monotonic() < deadline and not self._stop.is_set() and self.role == el.PRIMARY:
            if not f.connected():
                time.sleep(0.1)  # not connected yet: nobody to ask, nobody to tell
                continue
            others = [pid for _, pid in f.live_peers("sim", timeout=1.0) if pid != f.peer_id]
            replies = []
            if others:
                try:
                    replies = f.query(keys.srv(f.world, "state"), timeout=1.0, expected=WorldState, all_replies=True)
                except ServiceError:
                    replies = []  # standbys answer with a refusal: no other authority
            for rep in replies:
                if self._about_mine(rep.message):
                    self._heard(rep.message.header.source, rep.message.header.term)
            break
        if self.role == el.PRIMARY:
            if gap > lease:
                self._step(el.Resumed())
            f.unmuzzle()
            self.announce(f"sim {f.peer_id}: frozen {gap:.1f} s, still the authority (term {f.term})")

    # ------------------------------------------------------------------ standby

    def _followed(self, state: WorldState) -> str:
        return state.header.source

    def _poll(self) -> None:
        f = self.fabric
        while not self._stop.wait(self.poll_s):
            if self.role != el.STANDBY:
                return
            asked = time.monotonic()
            try:
                replies = f.query(keys.srv(f.world, "state"), timeout=1.0, expected=WorldState, all_replies=True)
            except ServiceError:
                continue
            best = max((r.message for r in replies if self._about_mine(r.message)), key=lambda m: m.header.term, default=None)
            if best is None:
                continue
            self._heard(best.header.source, best.header.term)
            with self._lock:
                if best.header.source == self.election.leader:
                    self.snapshot, self.snapshot_asked = best, asked

    def _about_mine(self, state: Any) -> bool:
        """Whether a ``srv/state`` answer is this shard's (another shard's terms are none of our election's)."""
        return isinstance(state, WorldState) and any(r.id in self.mine for r in state.robots)

    def _same_shard(self, peer_id: str) -> bool:
        """Whether a live sim belongs to this shard; one not asked yet counts as ours (one world, one shard:
        what every sim did before shards)."""
        with self._lock:
            robots = self.shards.get(peer_id)
        return robots is None or bool(robots & self.mine)

    def _learn_shards(self) -> None:
        """Ask every live sim which robots it serves (``srv/state`` with a shard query; standbys answer too)."""
        f = self.fabric
        try:
            replies = f.query(keys.srv(f.world, "state"), Event(kind=SHARD_QUERY, reason="ask"), timeout=1.0, expected=Event,
                              all_replies=True)
        except Exception:
            return  # nobody else (or closing): unknown sims count as ours
        with self._lock:
            for rep in replies:
                robots = rep.message.data.get("robots") if isinstance(rep.message.data, dict) else None
                if rep.message.kind == SHARD_QUERY and isinstance(robots, (list, tuple)) and rep.source:
                    self.shards[rep.source] = frozenset(str(r) for r in robots)
            for gone in [p for p in self.shards if p not in self.live]:
                del self.shards[gone]

    def _learn_shards_soon(self) -> None:
        """Learn a new sim's shard on a thread of its own (a token's callback must not wait for a query)."""
        with self._lock:
            if self._learning or self._closed:
                self._learn_again = True
                return
            self._learning, self._learn_again = True, False

        def run() -> None:
            while True:
                self._learn_shards()
                with self._lock:
                    if not self._learn_again or self._closed:
                        self._learning = False
                        live = frozenset(self.live)
                        break
                    self._learn_again = False
            if self._settled:
                self._step(el.Peers(self._shard_view(live)))

        threading.Thread(target=run, name="sim-shards", daemon=True).start()

    def _shard_view(self, live: frozenset[str]) -> frozenset[str]:
        """The live sims of this shard: the election of a shard counts no other shard's sims."""
        with self._lock:
            shards = dict(self.shards)
        return el.shard_view(live, shards, self.fabric.peer_id, self.mine)

    def _on_joints(self, key: str, js: JointState) -> None:
        rid = keys.parse(key).subject
        if rid in self._handed_out:
            self._drop_handed_out(rid, js.header.source, js.header.term)
        if rid not in self.mine:
            return  # another shard's robot: its term is its shard's
        self._heard(js.header.source, js.header.term)
        if self.role == el.STANDBY and js.header.source == self.election.leader:
            with self._lock:
                self.joints[keys.parse(key).subject] = js

    def _keep(self, key: str, msg: Any, size: int = 0) -> None:
        now = time.monotonic()
        with self._lock:
            if self.peer is not None:
                return  # serving: the peer takes commands itself (until it subscribes, they wait here)
            self.commands.append((now, key, msg, size))
            self._kept_bytes += size
            # the last seconds, and never more than a cap in count and bytes whatever clients send
            while self.commands and (
                self.commands[0][0] < now - KEEP_COMMANDS_S
                or len(self.commands) > MAX_KEPT_COMMANDS
                or self._kept_bytes > MAX_KEPT_BYTES
            ):
                self._kept_bytes -= self.commands.popleft()[3]

    def _on_command_sample(self, sample: Any) -> None:
        try:
            payload = sample.payload.to_bytes()
            self._keep(str(sample.key_expr), decode(payload, Command), len(payload))
        except DecodeError:
            pass  # the authority reports it; a standby keeps only what it could apply

    def _on_object(self, key: str, pose: Pose) -> None:
        self._keep(key, pose, 256)  # a pose is small and fixed in size (the codec caps its frame)

    def _on_pose(self, key: str, p: Pose) -> None:
        if keys.parse(key).subject not in self.mine:
            return
        if self.role == el.STANDBY and p.header.source == self.election.leader:
            with self._lock:
                self.poses[keys.parse(key).subject] = p

    def _await_leader(self, leader: str) -> None:
        """A standby that already follows ``leader`` (a primary that just stepped down on hearing its higher
        term) waits up to a transport lease for its token: the first liveliness query of a fresh session
        can answer before the router's tokens have reached it (seen in the lab after a healed partition:
        the view held only our own token, and the stepped-down primary took the world back at once, with
        its own stale state). A leader whose token does not show within the lease is gone: take over."""
        if self.role != el.STANDBY or not leader or leader == self.fabric.peer_id:
            return
        deadline = time.monotonic() + self.fabric.config.lease_ms / 1000.0
        while time.monotonic() < deadline and not self._stop.is_set():
            with self._lock:
                if leader in self.live:
                    return
            time.sleep(0.02)

    def _on_sim(self, kind: str, peer_id: str, alive: bool) -> None:
        with self._lock:
            (self.live.add if alive else self.live.discard)(peer_id)
            if not alive:
                self._gone_at[peer_id] = time.monotonic()
                if len(self._gone_at) > 256:  # made-up sim tokens must not grow this
                    self._gone_at.pop(min(self._gone_at, key=self._gone_at.__getitem__))
            live = frozenset(self.live)
            settled = self._settled
        if alive:
            self._learn_shards_soon()  # which shard it is (a standby of ours, or another shard's sim)
        if alive or not settled:
            return  # a token appearing (or the history repeating one) never starts a take-over; nor does
            # one going before the first view is settled (open() steps on the whole view then)
        self._step(el.Peers(self._shard_view(live)))
        if self.role == el.PRIMARY:
            self._adopt_soon()  # it may have been the scene objects' authority

    def _heard(self, source: str, term: int) -> None:
        if term > 0:
            self._step(el.Heard(source, term))

    def _step(self, ev: el.Event) -> None:
        with self._lock:
            self.election, effects = el.step(self.election, ev)
        for e in effects:
            if e.kind == "take_over":
                t = threading.Thread(target=self._take_over, args=(time.monotonic(),), name="take-over", daemon=True)
                self._taking_over = t
                t.start()
            elif e.kind == "step_down":
                self.fabric.muzzle()  # from now on nothing with the old term goes out
                self.announce(f"sim {self.fabric.peer_id}: {e.leader} holds term {e.term}; stepping down to standby")
                self._stepped_down.set()
            elif e.kind == "reassert":
                with self._lock:
                    self.fabric.assume_term(e.term, self._scopes())
            elif e.kind == "follow" and self.role == el.STANDBY:
                self.announce(f"standby {self.fabric.peer_id}: following {e.leader} (term {e.term})")

    def _take_over(self, t0: float) -> None:
        if self._stop.is_set():
            return  # closing: a world that is going away is not served again
        with self._lock:
            state = self.snapshot
        if state is None:
            self.announce(f"sim {self.fabric.peer_id}: took over with no state seen; the world starts from its scene")
        self._serve(state)
        took = time.monotonic() - t0
        self.takeovers.append({"term": self.election.term, "s": took, "from": state.header.source if state else ""})
        self.announce(f"sim {self.fabric.peer_id}: took over the world with term {self.election.term} in {took * 1000:.0f} ms"
                      + (f" from the state of {state.header.source} at t={state.time:.3f} s" if state else ""))


def run_replicated(
    open_fabric: Callable[[], Fabric],
    make_world: Callable[[], SimWorld],
    make_gate: GateFactory,
    stop: threading.Event,
    *,
    standby: bool,
    rates: dict[str, float] | None = None,
    speed: float | None = 1.0,
    duration: float | None = None,
    announce: Callable[[str], None] | None = None,
    objects: bool = True,
    rebuild: Callable[[list[SceneRobot]], SimWorld] | None = None,
) -> "ReplicaHost | None":
    """Run a sim peer until ``stop``: as primary or standby, a fresh session and world after each step-down.
    ``objects``: whether this sim is the scene objects' authority (the world's first sim; a shard that joins a
    served world is not). Returns the last host (its ``peer`` holds the counters when it served)."""
    term, leader = 0, ""
    last: WorldState | None = None
    host = None
    while not stop.is_set():
        with open_fabric() as fab:
            host = ReplicaHost(fab, make_world(), make_gate, standby=standby, rates=rates, speed=speed, term=term, leader=leader,
                        snapshot=last, announce=announce, objects=objects, rebuild=rebuild)
            role = host.run(stop, duration)
            term, leader, objects = host.election.term, host.election.leader, host.objects
            last = host.last_state
        if role != el.STANDBY or stop.is_set():
            return host
        standby = True
    return host
