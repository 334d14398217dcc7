"""Replicated authority: a sim peer as a world's primary or as a standby that takes it over.

:class:`ReplicaHost` runs one fabric session in one role at a time, driven by the pure election core
(:mod:`sim_peer.replica.election`), and composes one part per concern, each with its own module:

- :mod:`sim_peer.replica.roles` (:class:`~sim_peer.replica.roles.Roles`): the live sims, the election's state, its effects;
- :mod:`sim_peer.replica.following` (:class:`~sim_peer.replica.following.Follower`): the leader's last state, the streams and
  commands since (:mod:`sim_peer.replica.kept_commands`), and the world restored from them at a take-over;
- :mod:`sim_peer.shards.directory` (:class:`~sim_peer.shards.directory.ShardDirectory`): which live sim serves which robots;
- :mod:`sim_peer.replica.adoption` (:class:`~sim_peer.replica.adoption.ObjectAdoption`): the scene objects after their sim;
- :mod:`sim_peer.replica.freeze_guard` (:class:`~sim_peer.replica.freeze_guard.FreezeGuard`): a primary back from a freeze;
- :mod:`sim_peer.shards.moving` (:class:`~sim_peer.shards.moving.MoveService`): moving a robot between sims;
- :mod:`sim_peer.replica.deaf_stop` (:class:`~sim_peer.replica.deaf_stop.DeafStop`): a primary that hears no one stops its robots;
- :mod:`sim_peer.replica.role_token` (:class:`~sim_peer.replica.role_token.RoleToken`): the role it shows on the fabric, which tests
  and the soak read (``peer/sim/{id}/{role}/{term}/{leader}``).

The roles:

- **primary**: a :class:`~sim_peer.serving.peer.SimPeer` with its ownership gate, every message stamped with
  the term (``fabric.stamp.term``), and the whole world state served on ``rf/{world}/srv/state``
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

A host that stepped down returns from :meth:`ReplicaHost.run`; the caller opens a fresh session and runs a
standby (:func:`run_replicated`), so nothing the primary declared survives the change of role.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import replace
from typing import Any, Callable

from fabric import keys
from fabric.gate import CommandGate
from fabric.heap import HeapTrimmer
from fabric.interfaces import Event, Header, ServiceError, WorldState
from fabric.session import Fabric
from robots.description import SceneRobot
from sim_peer.replica import election as el
from sim_peer.shards import handoff as ho
from sim_peer.physics import capture
from sim_peer.replica.adoption import ObjectAdoption
from sim_peer.replica.deaf_stop import DeafStop
from sim_peer.replica.following import POLL_S, Follower
from sim_peer.replica.freeze_guard import FreezeGuard
from sim_peer.shards.moving import MoveService
from sim_peer.serving.peer import SimPeer
from sim_peer.replica.role_token import RoleToken
from sim_peer.replica.roles import Roles
from sim_peer.shards.directory import SHARD_QUERY, ShardDirectory
from sim_peer.serving.state_answers import StateAnswers
from sim_peer.physics.world import SimWorld

log = logging.getLogger("robofabric.sim")

__all__ = ["ReplicaHost", "run_replicated", "GateFactory"]

GateFactory = Callable[[Fabric, SimWorld, Any], Any]


class ReplicaHost:
    """One session of one sim peer in one role; ``run`` returns when stopped or after stepping down.

    It owns the one ``clock`` its parts read and composes them: ``roles``, ``shards``, ``follower``, ``freeze``,
    ``adoption``, ``moves`` and ``deaf_stop`` each get only their collaborators (docs/sim.md, "How the parts talk")
    and guard their own state with their own locks. Its ``lock`` guards what it serves (``peer``, ``gate``,
    ``world``, ``objects``); the election, the follower's kept commands and the robots the moves handed out change
    with that, so those parts get it too, as ``serving_lock``; ``stopping`` is set when it closes."""

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
        plant: str = "",
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fabric = fabric
        self.clock = clock  # monotonic seconds: the one clock every part reads (a fake one in tests)
        self.plant = plant  # a test-only defect for the soak's checker (fabric/plant.py); "" in every real world
        # builds this sim's world again with other robots (the same scene and options): a robot moved in or out
        self.rebuild = rebuild
        # the scene objects' authority: the world's first sim (a shard joining a served world is not); a standby
        # learns it from its leader's state at a take-over (a primary that is not describes no objects there)
        self.objects = objects
        self.world = world
        self.make_gate = make_gate
        self.rates = rates
        self.speed = speed
        self.announce = announce or (lambda text: log.info("%s", text))
        me = fabric.peer_id
        election = el.Election(me, el.STANDBY, term, leader) if standby else el.start(me, standby=False, term=term + 1)
        self.lock = threading.RLock()
        self.stopping = threading.Event()
        self._closed = False
        self._duration: float | None = None
        self.peer: SimPeer | None = None
        self.gate: CommandGate | None = None
        self.takeovers: list[dict[str, Any]] = []
        self.last_state: WorldState | None = None
        self.role_token = RoleToken(fabric)  # the role shown on the fabric (sim_peer.replica.role_token)
        # this shard: the robots this sim serves, or would at a take-over
        self.shards = ShardDirectory(
            fabric,
            world.robots,
            live=lambda: self.roles.live_sims(),
            stopping=self.stopping,
            on_learnt=lambda view: self.roles.shards_learnt(view),
        )
        self.roles = Roles(
            fabric,
            election,
            shard=self.shards,
            serving_lock=self.lock,
            stopping=self.stopping,
            announce=self.announce,
            take_over=self.take_over,
            reassert=self._reassert,
            show_role=self._show_role,
            adopt_soon=lambda: self.adoption.soon(),
            clock=clock,
        )
        self.follower = Follower(
            fabric,
            world=lambda: self.world,
            election=lambda: self.roles.election,
            shard=self.shards,
            heard=self.roles.heard,
            seen_serving=lambda *seen: self.moves.seen_serving(*seen),
            serving=lambda: self.serving,
            serving_lock=self.lock,
            stopping=self.stopping,
            clock=clock,
            snapshot=snapshot,
            poll_s=poll_s,
            plant=plant,
            announce=self.announce,
            kept=lambda: self._show_role(self.roles.election),  # a standby's role shows once it holds a state
        )
        self.freeze = FreezeGuard(
            fabric,
            roles=self.roles,
            shard=self.shards,
            stopping=self.stopping,
            announce=self.announce,
            gap=freeze_gap,
            clock=clock,
        )
        self.adoption = ObjectAdoption(
            fabric, self, stopping=self.stopping, announce=self.announce, clock=self.clock, after_s=adopt_after_s
        )
        self.moves = MoveService(
            fabric,
            self,
            serving_lock=self.lock,
            election=lambda: self.roles.election,
            live=self.roles.live_sims,
            standbys=self.shards.standbys,
            announce=self.announce,
            clock=clock,
        )
        # a primary that hears no one stops its robots
        self.deaf_stop = DeafStop(
            fabric,
            hearing=self.roles,
            serving=lambda: self.peer if self.role == el.PRIMARY else None,
            stopping=self.stopping,
            announce=self.announce,
            clock=clock,
        )
        self.state_answers = StateAnswers(
            fabric.counters
        )  # srv/state off zenoh's callback thread (sim_peer.serving.state_answers)

    # ------------------------------------------------------------------ lifecycle

    @property
    def role(self) -> str:
        return self.roles.election.role

    @property
    def election(self) -> el.Election:
        return self.roles.election

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def serving(self) -> bool:
        """Whether its peer serves the world now (a primary between two rebuilds does not)."""
        return self.peer is not None

    def open(self, duration: float | None = None) -> "ReplicaHost":
        f, w = self.fabric, self.fabric.world
        self._duration = duration
        f.rpc.serve(keys.srv(w, "state"), self._on_state_query, defer=self.state_answers.route)  # apart, bounded
        f.rpc.serve(keys.srv_move_served(w, f.peer_id), self.moves.on_query, expected=Event)
        if self.role == el.PRIMARY:
            self.serve(None)  # the world first: nothing below may delay a primary's streams and services
        # other sims' streams only: a primary hears a rival's term there, a standby its leader's state
        self.follower.listen(standby=self.role != el.PRIMARY)
        self.roles.join()
        if self.role != el.PRIMARY:
            self.follower.start_polling()
            self.announce(
                f"standby {f.peer_id}: following {self.election.leader or 'the primary'} (term {self.election.term})"
            )
        self._show_role(self.election)
        return self

    def run(self, stop: threading.Event, duration: float | None = None) -> str:
        """Serve or follow until ``stop`` or a step-down; returns the role it ended in."""
        self.open(duration)
        try:
            while not stop.is_set() and not self.roles.stepped_down.is_set():
                stop.wait(0.1)
                with self.lock:  # a robot moving in or out rebuilds under the lock: its closed peer is not the end
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
        with self.lock:
            if self._closed:
                return
            self._closed = True
        self.stopping.set()
        self.role_token.close()
        self.moves.close()
        self.state_answers.close()
        # a take-over under way finishes first: closed meanwhile, it raised from its thread and could
        # start a peer after close() had looked for one
        taking = self.roles.taking_over
        if taking is not None and taking is not threading.current_thread():
            taking.join(10.0)
        if self.peer is not None and self.role == el.STANDBY:  # stepped down: keep what we had, in case
            try:
                self.last_state = self.world_state(force=True)
            except Exception:
                log.debug("no state kept at step-down", exc_info=True)
        self.follower.join(2.0)
        if self.peer is not None:
            self.peer.close()
        if self.gate is not None:
            self.gate.close()

    # ------------------------------------------------------------------ serving

    def serve(self, state: WorldState | None) -> None:
        """Serve the world as its authority with the current term, from ``state`` when taking over."""
        f = self.fabric
        restored = None
        with self.lock:
            if state is not None:
                restored = self.follower.catch_up(state)
            if state is not None and self.world.objects:
                self.objects = bool(state.objects)  # the shard we take over was the objects' authority, or not
            f.assume_term(self.election.term, self.scopes())
        self.freeze.watch()
        if self.objects:
            self.gate = self.make_gate(f, self.world, restored)
        else:
            self.gate = self.make_gate(f, self.world, restored, objects=False)
        self.peer = SimPeer(f, self.world, gate=self.gate, rates=self.rates, speed=self.speed, objects=self.objects)
        if state is not None:
            self.follower.replay(self.peer, self.gate)
        self.peer.start(self._duration)
        self.deaf_stop.watch()

    def _show_role(self, election: el.Election) -> None:
        """Show the role ``election`` gives (sim_peer/replica/role_token.py): a standby's once it holds a state."""
        follower = getattr(self, "follower", None)  # the election may speak before the follower is made
        holds = follower is not None and follower.holds_state()
        self.role_token.show(election, self.peer is not None, holds)

    def _reassert(self, term: int) -> None:
        """Assert ``term`` again over what this sim serves (the election's effect after a freeze)."""
        with self.lock:
            self.fabric.assume_term(term, self.scopes())

    def scopes(self) -> tuple[str, ...]:
        """What this sim is the authority of: its robots, and the scene objects when it is their authority."""
        return tuple(self.world.robots) + (tuple(self.world.objects) if self.objects else ())

    def take_over(self, t0: float, former: str | None = None) -> None:
        """Serve the world from the last state heard (the election's take-over, on a thread of its own);
        ``former``: the leader followed until now, whose streams still on their way in are waited for."""
        if self.stopping.is_set():
            return  # closing: a world that is going away is not served again
        if former:
            self.follower.drain(former)
        with self.lock:
            state = self.follower.snapshot
        if state is None:
            self.announce(f"sim {self.fabric.peer_id}: took over with no state seen; the world starts from its scene")
        try:
            self.serve(state)
        finally:
            self.follower.drained()
        took = self.clock() - t0
        self.takeovers.append({"term": self.election.term, "s": took, "from": state.header.source if state else ""})
        self.announce(
            f"sim {self.fabric.peer_id}: took over the world with term {self.election.term} in {took * 1000:.0f} ms"
            + (f" from the state of {state.header.source} at t={state.time:.3f} s" if state else "")
        )
        self._show_role(self.election)

    def world_state(self, *, force: bool = False) -> WorldState:
        """The whole world's state as this sim serves it (``force``: a standby that served until now, too)."""
        peer = self.peer
        if peer is None or (self.role != el.PRIMARY and not force):
            raise ServiceError(f"{self.fabric.peer_id} is a standby (term {self.election.term})")
        records, users = self.gate.export_state()
        with peer.lock:
            t, steps, robots, objects = capture.capture(self.world)
        if not self.objects:
            objects = ()  # the objects' authority is another shard: its standby must not become it
        seqs = self.fabric.seqs.under(keys.world_root(self.fabric.world))
        return WorldState(
            t,
            steps,
            robots,
            objects,
            tuple(records),
            dict(users),
            seqs,
            header=self.fabric.header(keys.srv(self.fabric.world, "state"), stamp=t),
        )

    def _on_state_query(self, key: str, request: Any) -> WorldState | Event:
        if isinstance(request, Event) and request.kind == SHARD_QUERY:
            # which shard this sim belongs to, primary or standby: its robots (an election counts the sims of its shard)
            return self.shards.answer(self.role)
        if isinstance(request, Event) and request.kind in ho.STEPS:
            # every login may ask srv/state: a move asked here is refused, whoever asks (moves: srv/move, the staff's)
            raise self.moves.refused(
                request,
                "",
                "moves are for the instructor and sim logins: srv/state, which every login "
                "may ask, moves nothing (robofabric own move asks srv/move/SIM/by/LOGIN)",
            )
        return self.world_state()

    # ------------------------------------------------------------------ rebuilding (a robot moved, the objects adopted)

    def stop_serving(self) -> tuple[WorldState, dict[str, SceneRobot]]:
        """Stop the peer and the gate (call with the lock held); the world's state as they left it."""
        f, peer = self.fabric, self.peer
        f.stamp.watch_freeze(None, None)  # a rebuild is not a freeze
        peer.close()
        records, users = self.gate.export_state()
        self.gate.close()
        with peer.lock:
            t, steps, robots, objects = capture.capture(self.world)
        state = WorldState(
            t,
            steps,
            robots,
            objects if self.objects else (),
            tuple(records),
            dict(users),
            {},
            header=Header(wall_ns=time.time_ns(), source=f.peer_id),
        )
        self.peer = self.gate = None
        return state, dict(self.world.placements)

    def serve_rebuilt(self, world: SimWorld, state: WorldState, term: int, seqs: dict[str, int]) -> None:
        """Serve ``world`` (built with the robots it is to serve), restored to ``state``, under ``term`` (the
        take-over path)."""
        self.world = world
        self.shards.mine = frozenset(self.world.robots)
        self.roles.set_term(term)
        self.fabric.seqs.carry_on(seqs)
        self.serve(replace(state, header=replace(state.header, term=term)))
        self.role_token.show(self.election, True)  # serving again, under the new term
        self.shards.learn_soon()

    def serves_objects(self) -> bool:
        """Whether no adoption is wanted here: this sim is the scene objects' authority already, or closed."""
        with self.lock:
            return self.objects or self._closed

    def scene_objects(self) -> tuple[str, ...]:
        """The scene objects of the world this sim builds (:class:`~sim_peer.replica.adoption.ObjectsServer`)."""
        return tuple(self.world.objects)

    def adopt_objects(self) -> int | None:
        """Serve the scene objects with this sim's robots, one term up (what it serves and its term change together,
        under the lock); the new term, or None when it is not a serving primary, serves them already, or closed."""
        with self.lock:
            if self.role != el.PRIMARY or self.peer is None or self.objects or self._closed:
                return None
            self.objects = True  # before the capture: the state carries the objects where this sim mirrored them
            state, _ = self.stop_serving()
            term = self.election.term + 1
            self.roles.set_term(term)
            self.serve(replace(state, header=replace(state.header, term=term)))
            self.role_token.show(self.election, True)  # serving again, under the new term
        return term

    def serve_again(self, placements: dict[str, SceneRobot], state: WorldState, term: int) -> None:
        """After a rebuild that failed half-way: whatever started is closed and the old robots served again, at the
        term the failed rebuild took (never lower: anything it published was stamped with it)."""
        for part in (self.peer, self.gate):
            if part is not None:
                try:
                    part.close()
                except Exception:
                    log.debug("closing after a failed rebuild", exc_info=True)
        self.peer = self.gate = None
        self.serve_rebuilt(self.rebuild(list(placements.values())), state, term, {})


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
    plant: str = "",
) -> "ReplicaHost | None":
    """Run a sim peer until ``stop``: as primary or standby, a fresh session and world after each step-down.
    ``objects``: whether this sim is the scene objects' authority (the world's first sim; a shard that joins a
    served world is not). ``plant``: a test-only defect (fabric/plant.py). Returns the last host (its ``peer``
    holds the counters when it served)."""
    term, leader = 0, ""
    last: WorldState | None = None
    host = None
    with HeapTrimmer():  # what zenoh's threads free through its hours of faults goes back (fabric.heap)
        while not stop.is_set():
            with open_fabric() as fab:
                host = ReplicaHost(
                    fab,
                    make_world(),
                    make_gate,
                    standby=standby,
                    rates=rates,
                    speed=speed,
                    term=term,
                    leader=leader,
                    snapshot=last,
                    announce=announce,
                    objects=objects,
                    rebuild=rebuild,
                    plant=plant,
                )
                role = host.run(stop, duration)
                term, leader, objects = host.election.term, host.election.leader, host.objects
                last = host.last_state
            if role != el.STANDBY or stop.is_set():
                return host
            standby = True
    return host
