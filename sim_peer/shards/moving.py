"""A sim's side of moving a robot between sims: its ``srv/move/{sim}/by/{login}`` service.

The protocol and its pure helpers are :mod:`sim_peer.shards.handoff`. A move is two rebuilds on the take-over path
(:meth:`sim_peer.replica.replica_host.ReplicaHost.serve_rebuilt`): the source stops serving the robot and keeps it
(:class:`~sim_peer.shards.handoff.HandedOut`) until its target fetched it and serves it, or it takes it back; a target
serves only what it fetched from the source. ``srv/move`` is the staff's key; a move asked on ``srv/state``,
which every login may ask, is refused (:meth:`MoveService.refused`). Whether a step may be taken now is the pure
core :mod:`sim_peer.shards.move_rule`'s decision; this shell gathers what the server holds, asks, rebuilds and serves.

It talks to the rest of the sim through what its constructor names, never the host: the ``fabric``, the server it
rebuilds (:class:`Rebuilder`), the election's state, the live sims and this shard's standbys, ``announce`` and the
host's ``clock``. The robots it handed out change together with the world the server serves (a robot is either
served or kept, never both nor neither), so both are guarded by one lock, the server's ``serving_lock``, passed in.
"""

from __future__ import annotations

import logging
import secrets
import threading
import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable, Iterable, Protocol

from fabric import keys
from fabric.codec import decode, encode
from fabric.interfaces import Event, EventKind, ServiceError, WorldState
from fabric.limits import clip
from robots.description import DescriptionError, SceneRobot
from sim_peer.replica import election as el
from sim_peer.shards import handoff as ho
from sim_peer.shards import move_rule as mr
from sim_peer.physics.errors import WorldError
from sim_peer.physics.registry import robot_class

if TYPE_CHECKING:
    from fabric.session import Fabric
    from sim_peer.physics.world import SimWorld

log = logging.getLogger("robofabric.sim")

__all__ = ["MoveService", "Rebuilder", "MOVE_ASK_S"]

MOVE_ASK_S = 2.0
"""How long a sim waits for another's answer to a step of a move (a round trip; the other may be rebuilding)."""


class Rebuilder(Protocol):
    """What a move asks of the sim that serves (the replica's host): its world, and serving it rebuilt."""

    world: "SimWorld"
    rebuild: "Callable[[list[SceneRobot]], SimWorld] | None"

    @property
    def closed(self) -> bool:
        """Whether the server closed (a robot kept for a move is not served again then)."""
        ...

    @property
    def serving(self) -> bool:
        """Whether its peer serves the world now."""
        ...

    def stop_serving(self) -> tuple[WorldState, dict[str, SceneRobot]]:
        """Stop serving; the world's state as it left it and its robots' placements."""
        ...

    def serve_rebuilt(self, world: "SimWorld", state: WorldState, term: int, seqs: dict[str, int]) -> None:
        """Serve ``world``, restored to ``state``, under ``term``."""
        ...

    def serve_again(self, placements: dict[str, SceneRobot], state: WorldState, term: int) -> None:
        """Serve the old robots again after a rebuild that failed half-way."""
        ...


class MoveService:
    """The steps of a move as one sim answers them, and the robots it handed out and keeps."""

    def __init__(
        self,
        fabric: "Fabric",
        server: Rebuilder,
        *,
        serving_lock: threading.RLock,
        election: Callable[[], el.Election],
        live: Callable[[], frozenset[str]],
        standbys: Callable[[Iterable[str]], list[str]],
        announce: Callable[[str], None],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fabric = fabric
        self.server = server
        self.lock = serving_lock  # the server's: what it serves and the robots handed out change together
        self._election, self._live, self._standbys = election, live, standbys
        self.announce = announce
        self.clock = clock
        self.login = fabric.config.identity() or fabric.peer_id  # it asks other sims in its own name
        self.handed_out: dict[str, ho.HandedOut] = {}  # under the serving lock
        self._timers: list[threading.Timer] = []  # take back what no target fetched

    def close(self) -> None:
        for timer in self._timers:
            timer.cancel()

    def on_query(self, key: str, request: Any) -> Event | None:
        """One step of a move (:mod:`sim_peer.shards.handoff`) asked on ``srv/move/{me}/by/{login}``: the staff's key (a
        class's router lets the instructor and sim logins ask there, each in its own name). A refusal is answered
        with its reason, counted (``moves_refused``), logged and published on ``event/move``."""
        try:
            asker = keys.asker(keys.parse(key))
        except ValueError:
            asker = ""
        if not isinstance(request, Event) or request.kind not in ho.STEPS:
            raise self.refused(request, asker, f"a move's step is an Event of kind {', '.join(ho.STEPS)}")
        try:
            return self._step(request, asker)
        except (ServiceError, ho.MoveError, WorldError, DescriptionError, ValueError) as exc:
            raise self.refused(request, asker, exc.reason if isinstance(exc, ServiceError) else str(exc)) from None

    def refused(self, request: Any, asker: str, reason: str) -> ServiceError:
        """Count, log and publish a refused step of a move; the error its asker gets."""
        f = self.fabric
        f.counters["moves_refused"] += 1
        kind = request.kind if isinstance(request, Event) and request.kind in ho.STEPS else "other"
        robot = request.object if isinstance(request, Event) else ""
        ev = Event(
            kind=EventKind.MOVE_REFUSED,
            reason=clip(reason, 400),
            object=clip(str(robot), 64),
            user=clip(asker, 64),
            severity="warning",
            data={"step": kind},
            header=f.header("event"),
        )
        if self._election().role == el.PRIMARY:
            f.reports.emit(ev, "move", limit=f"move_refused:{kind}")  # kind: a fixed word, never client text
        else:
            log.warning("move refused (%s, by %s): %s", kind, asker or "?", clip(reason, 400))
        return ServiceError(reason)

    def seen_serving(self, rid: str, sim: str, term: int) -> None:
        """``sim`` serves ``rid`` at ``term`` (its joints came): what this sim kept of it is no longer to be taken back."""
        if rid not in self.handed_out:
            return
        with self.lock:
            kept = self.handed_out.get(rid)
            if kept is not None and mr.served_there(kept.to, kept.handoff.term, sim, term):
                del self.handed_out[rid]

    def _step(self, request: Event, asker: str) -> Event | None:
        me, d = self.fabric.peer_id, request.data if isinstance(request.data, dict) else {}
        rid = keys.validate_id(request.object, what="robot id")
        to, source, move_id = str(d.get("to", "")), str(d.get("from", "")), str(d.get("move", ""))
        term = d.get("term", 0)
        if not isinstance(term, int) or isinstance(term, bool):
            raise ho.MoveError(f"a move's term is an integer, got {clip(repr(term), 40)}")
        if request.kind == ho.MOVE_CHECK:
            with self.lock:
                self._check_mover()
                return ho.step(ho.MOVE_CHECK, rid, to=to, source=me, term=self._election().term, asker=me)
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
        why = mr.mover_refusal(
            self.fabric.peer_id,
            serving=self._election().role == el.PRIMARY and self.server.serving,
            can_rebuild=self.server.rebuild is not None,
            standbys=self._standbys(self._live()),
        )
        if why:
            raise ServiceError(why)

    def _rebuild(self, placements: list[SceneRobot]) -> "SimWorld":
        """The server's world built again with ``placements`` (a mover has a rebuild: :meth:`_check_mover`)."""
        rebuild = self.server.rebuild
        if rebuild is None:
            raise ServiceError(f"sim {self.fabric.peer_id} cannot rebuild its world")
        return rebuild(placements)

    def _ask_sim(self, sim: str, request: Event) -> Event:
        """Ask another sim one step of a move in this sim's login (a sim login may ask ``srv/move``)."""
        return ho.ask(self.fabric, sim, self.login, request, MOVE_ASK_S)

    def _move_out(self, rid: str, to: str, term: int, asker: str) -> Event:
        """The source's step: the target's word first (it would take the robot, and its term), then the robot
        handed out and kept for it (:meth:`_hand_out`). A target that is not there or would not take it, or a term
        that is not the election's, changes nothing."""
        me = self.fabric.peer_id
        with self.lock:
            self._check_mover()
            why = mr.move_out_refusal(
                rid,
                to,
                me,
                robots=self.server.world.robots,
                handed_out=self.handed_out,
                live=self._live(),
                world=self.fabric.world,
            )
            if why:
                raise ho.MoveError(why)
            my_term, rtype = self._election().term, self.server.world.robots[rid].desc.name
        # outside the lock: the target's answer takes a round trip, and this sim keeps serving meanwhile
        answer = self._ask_sim(to, ho.step(ho.MOVE_PREPARE, rid, to=to, source=me, term=term, rtype=rtype, asker=me))
        theirs = answer.data.get("term") if isinstance(answer.data, dict) else None
        if not isinstance(theirs, int) or isinstance(theirs, bool):
            raise ho.MoveError(f"sim {to} did not say its term")
        want = ho.move_term(my_term, theirs)
        if term != want:
            raise ho.MoveError(
                f"move term {term} is not the one the election gives ({want}: above sim {me}'s term {my_term} "
                f"and sim {to}'s {theirs}): ask again"
            )
        with self.lock:
            self._check_mover()
            if not mr.unchanged(
                rid,
                term=self._election().term,
                asked_at_term=my_term,
                robots=self.server.world.robots,
                handed_out=self.handed_out,
            ):
                raise ho.MoveError(f"sim {me} changed while sim {to} was asked: ask again")
            return self._hand_out(rid, to, term, asker)

    def _prepare(self, rid: str, source: str, rtype: str) -> Event:
        """The target's word before a source lets a robot go: it serves, does not serve ``rid``, and has its type
        installed (a NAME, found among this machine's robots: :func:`robots.installed`); its answer gives its term."""
        import robots

        me = self.fabric.peer_id
        with self.lock:
            self._check_mover()
            if rid in self.server.world.robots:
                raise ho.MoveError(f"sim {me} already serves {rid}")
            term = self._election().term
        robot_class(robots.installed(rtype))  # the operator's plug-in, by name; a path is refused, never read
        return ho.step(ho.MOVE_PREPARE, rid, to=me, source=source, term=term, asker=me)

    def _fetch(self, rid: str, to: str, term: int, move_id: str, decline: bool) -> Event:
        """The source's answer to its target: the robot it handed out to that sim in that move at that term
        (``decline``: the target gives it back, having served nothing of it)."""
        me = self.fabric.peer_id
        with self.lock:
            kept = self.handed_out.get(rid)
            why = ho.fetch_refusal(kept, rid, to, term, move_id)
            if why:
                raise ho.MoveError(why)
            assert kept is not None
            self.handed_out[rid] = replace(kept, fetched=not decline)
        if decline:
            return ho.step(ho.MOVE_FETCH, rid, to=to, source=me, term=term, move_id=move_id, asker=me, decline=True)
        return ho.to_event(ho.MOVE_FETCH, rid, to, kept.handoff, term=term, source=me)

    def _hand_out(self, rid: str, to: str, term: int, asker: str) -> Event:
        """Stop serving ``rid`` and keep it for ``to`` (call with the lock held). The world without it is built
        before anything stops: a world that cannot be built changes nothing."""
        t0, me = self.clock(), self.fabric.peer_id
        placements = dict(self.server.world.placements)
        rest_world = self._rebuild([p for r, p in placements.items() if r != rid])
        rtype = self.server.world.robots[rid].desc.name
        state, placements = self.server.stop_serving()
        robot = next(r for r in state.robots if r.id == rid)
        record = next((r for r in state.records if r.object == rid), None)
        seqs = self.fabric.seqs.under(keys.world_root(self.fabric.world) + f"/robot/{rid}/")
        handoff = ho.Handoff(
            robot, replace(placements[rid], type=rtype), record, ho.named_users(state.users, record), seqs, term, me
        )
        rest = replace(
            state,
            robots=tuple(r for r in state.robots if r.id != rid),
            records=ho.merge_records(state.records, drop=rid),
        )
        try:
            ho.from_event(
                decode(encode(ho.to_event(ho.MOVE_FETCH, rid, to, handoff, term=term, source=me)), Event)
            )  # it can travel
            self.server.serve_rebuilt(rest_world, rest, term, {})
        except Exception as exc:
            log.exception("handing %s out failed", rid)
            self.server.serve_again(placements, state, self._election().term)
            raise ServiceError(f"sim {me} could not hand {rid} out ({exc}); it keeps serving it") from None
        move_id = secrets.token_hex(8)
        self.handed_out[rid] = ho.HandedOut(handoff, to, move_id, placement=placements[rid], at=self.clock())
        timer = threading.Timer(ho.RETURN_AFTER_S, self._return_unclaimed, args=(rid, move_id))
        timer.daemon = True
        timer.start()
        self._timers.append(timer)
        self.announce(
            f"sim {me}: handed {rid} out to {to} (term {term}) in {(self.clock() - t0) * 1000:.0f} ms"
            + (f", asked by {asker}" if asker else "")
        )
        return ho.step(ho.MOVE_OUT, rid, to=to, source=me, term=term, move_id=move_id, asker=me)

    def _move_in(self, rid: str, source: str, term: int, move_id: str, asker: str) -> Event:
        """The target's step: the robot fetched from its source (never taken from the query), checked, served. A
        refusal after the fetch gives it back to the source, which may then serve it again."""
        import robots

        me = self.fabric.peer_id
        with self.lock:
            self._check_mover()
            why = mr.move_in_refusal(rid, me, term=term, my_term=self._election().term, robots=self.server.world.robots)
            if why:
                raise ho.MoveError(why)
        handoff = ho.from_event(
            self._ask_sim(
                source, ho.step(ho.MOVE_FETCH, rid, to=me, source=source, term=term, move_id=move_id, asker=me)
            )
        )
        try:
            ho.check_handoff(handoff, rid, source, term)
            desc = robots.installed(handoff.placement.type)  # a name: the operator's installed robot, never a path
            robot_class(desc)
            with self.lock:
                self._check_mover()
                if rid in self.server.world.robots or term < self._election().term:
                    raise ho.MoveError(f"sim {me} changed while sim {source} was asked: ask again")
                self._take_in(handoff, replace(handoff.placement, type=str(desc.directory / "robot.toml")), term, asker)
        except BaseException:
            self._give_back(source, rid, term, move_id)
            raise
        return ho.step(ho.MOVE_IN, rid, to=me, source=source, term=term, move_id=move_id, asker=me)

    def _give_back(self, source: str, rid: str, term: int, move_id: str) -> None:
        me = self.fabric.peer_id
        try:
            self._ask_sim(
                source,
                ho.step(ho.MOVE_FETCH, rid, to=me, source=source, term=term, move_id=move_id, asker=me, decline=True),
            )
        except ho.MoveError as exc:
            log.warning("could not give %s back to sim %s: %s", rid, source, exc)

    def _take_in(self, handoff: ho.Handoff, placement: SceneRobot, term: int, asker: str = "") -> None:
        """Serve ``handoff``'s robot placed at ``placement`` with this sim's own (call with the lock held). The
        new world is built before anything stops; a failure after the stop serves the old world again."""
        t0, me = self.clock(), self.fabric.peer_id
        rid = handoff.state.id
        world = self._rebuild([*self.server.world.placements.values(), placement])
        state, placements = self.server.stop_serving()
        full = replace(
            state,
            robots=(*state.robots, handoff.state),
            records=ho.merge_records(state.records, add=handoff.record),
            users=ho.merge_users(state.users, handoff.users),
        )
        try:
            self.server.serve_rebuilt(world, full, term, dict(handoff.seqs))
        except Exception as exc:
            log.exception("taking %s in failed", rid)
            self.server.serve_again(placements, state, self._election().term)
            raise ServiceError(f"sim {me} could not serve {rid} ({exc}); it serves what it served") from None
        self.announce(
            f"sim {me}: took {rid} in from {handoff.source or 'another sim'} (term {term}) in "
            f"{(self.clock() - t0) * 1000:.0f} ms" + (f", asked by {asker}" if asker else "")
        )

    def _take_back(self, rid: str, move_id: str | None, asker: str) -> Event:
        """The source serves a robot it handed out again, as it kept it (``move_id`` None: its own timer)."""
        me = self.fabric.peer_id
        with self.lock:
            self._check_mover()
            kept = self.handed_out.get(rid)
            why = ho.take_back_refusal(kept, rid, move_id, kept is not None and kept.to in self._live())
            if why:
                raise ho.MoveError(why)
            assert kept is not None and kept.placement is not None  # _hand_out keeps every robot's placement
            if rid in self.server.world.robots:
                raise ho.MoveError(f"sim {me} serves {rid} already")
            self._take_in(kept.handoff, kept.placement, self._election().term, asker or "this sim")
            del self.handed_out[rid]
        return ho.step(ho.MOVE_IN, rid, to=me, source=me, term=self._election().term, move_id=kept.move, asker=me)

    def _return_unclaimed(self, rid: str, move_id: str) -> None:
        """A robot handed out that no target fetched within :data:`~sim_peer.shards.handoff.RETURN_AFTER_S` (the tool
        died between its steps) is served here again."""
        with self.lock:
            kept = self.handed_out.get(rid)
            if not mr.unclaimed(
                closed=self.server.closed,
                kept_move=kept.move if kept is not None else None,
                move_id=move_id,
                fetched=kept is not None and kept.fetched,
            ):
                return
        try:
            self._take_back(rid, None, "")
        except (ServiceError, ho.MoveError) as exc:
            log.warning("could not serve %s again after its move: %s", rid, exc)
            return
        self.announce(
            f"sim {self.fabric.peer_id}: no sim took {rid} within {ho.RETURN_AFTER_S:.0f} s; serving it again"
        )
