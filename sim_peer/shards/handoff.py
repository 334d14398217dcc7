"""Moving a robot from one sim of a world to another (docs/sim.md, "Moving a robot between sims").

A compiled MuJoCo model cannot gain or lose bodies, so a move is two rebuilds on the standby's take-over path
(:meth:`sim_peer.replica.replica_host.ReplicaHost.serve_rebuilt`): the source stops serving, hands out the robot's state, its
placement, its ownership record and its streams' sequence numbers (a :class:`Handoff`) and goes on without it;
the target builds its world again with the robot added, restores every robot (its own from its world, the moved
one from the handoff) and serves it with its ownership record, so the owner keeps it and her epoch.

Moves are the staff's (instructor and sim logins): the operator's tool (:func:`move`, ``robofabric own move``)
asks each sim on ``srv/move/{sim}/by/{login}`` (:func:`fabric.keys.srv_move`), which a class's router opens to
those logins only; a sim refuses a move asked on ``srv/state``, which every login may ask. The tool carries no
robot: the source keeps what it handed out (:class:`HandedOut`) until the target fetches it from the source
itself (``move_fetch``, sim to sim), or the source takes it back. So a move_in can only serve a robot its source
handed out in that move, at that move's term, as the source captured it:

1. ``move_out`` (tool -> source): the source asks the target whether it would take the robot (``move_prepare``:
   the target serves, does not serve that robot, has its type installed) and its term, checks that the move's
   term is the one the election gives (``max(source, target) + 1``), then stops serving the robot and keeps it.
2. ``move_in`` (tool -> target): the target fetches the handoff from the source, checks it (the robot, the source,
   the term), builds its world with the robot before it stops serving its own, and serves it; a failure after it
   stopped serves its old world again. Should it refuse, the tool asks the source to take the robot back
   (``move_in`` to the source), which it does from what it kept (never from what the tool says).

Pure helpers here; the tool's I/O is :func:`move`.
"""

from __future__ import annotations

import base64
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

from fabric.codec import decode, encode
from fabric.interfaces import Event, Header, OwnershipRecord, RobotState, WorldState
from robots.description import SceneRobot

__all__ = [
    "MOVE_OUT",
    "MOVE_IN",
    "MOVE_CHECK",
    "MOVE_PREPARE",
    "MOVE_FETCH",
    "Handoff",
    "HandedOut",
    "MoveError",
    "move_term",
    "merge_records",
    "merge_users",
    "to_event",
    "from_event",
    "check_handoff",
    "fetch_refusal",
    "take_back_refusal",
    "step",
    "ask",
    "NoAnswer",
    "move",
]

MOVE_OUT = "move_out"
"""``Event.kind`` of a ``srv/move`` query asking the robot's sim to stop serving it and keep it for the target."""
MOVE_IN = "move_in"
"""``Event.kind`` of a ``srv/move`` query asking a sim to serve a handed-out robot (or, on failure, its source to
take it back)."""
MOVE_CHECK = "move_check"
"""``Event.kind`` of the tool's first ``srv/move`` query: does this sim answer moves asked in this login's name?"""
MOVE_PREPARE = "move_prepare"
"""``Event.kind`` of the source's query to the target before it stops serving: would it take the robot, at what term?"""
MOVE_FETCH = "move_fetch"
"""``Event.kind`` of the target's query to the source: the handoff it keeps for the target (``data["decline"]``:
the target gives it back, taking nothing)."""
STEPS = (MOVE_CHECK, MOVE_OUT, MOVE_PREPARE, MOVE_FETCH, MOVE_IN)
RETURN_AFTER_S = 30.0
"""A source takes a robot it handed out back by itself when no target fetched it within this long (the tool died
between its two steps): a robot is never left without a sim."""
CHECK_TIMEOUT_S = 3.0
"""How long the tool waits for the source's answer to its first ``srv/move`` query: no answer at all is how a
class's router refuses a login that may not move (it drops the query)."""


class MoveError(Exception):
    """A move that could not be made; the reason names what refused it."""


class NoAnswer(MoveError):
    """Nobody answered a step of a move on ``srv/move/{sim}/by/{login}`` (a class's router drops the query of a
    login that may not ask there: it sends no refusal)."""


@dataclass(frozen=True, slots=True)
class Handoff:
    """What a sim hands out with a robot: its controller state, its placement (type, id, spawn pose, where the
    target builds it, so a ``reset`` still sends it home), its ownership record (None without ownership), the users that record names (join ranks,
    liveness, as :func:`ownership.snapshot.export` writes them), its streams' next sequence numbers, and the term
    both sims serve under after the move."""

    state: RobotState
    placement: SceneRobot
    record: OwnershipRecord | None
    users: Mapping[str, Any] = field(default_factory=dict)
    seqs: Mapping[str, int] = field(default_factory=dict)
    term: int = 0
    source: str = ""


@dataclass(frozen=True, slots=True)
class HandedOut:
    """What a source keeps of a robot it handed out, until the target serves it or the source takes it back: the
    handoff itself, the sim it is for, the move's id (the tool names it in the ``move_in``), its own placement of
    it (to serve it again), whether the target fetched it, and when it was handed out (monotonic s)."""

    handoff: Handoff
    to: str
    move: str
    placement: SceneRobot | None = None  # where the source had it, its type as the source's operator named it
    fetched: bool = False
    at: float = 0.0


def fetch_refusal(kept: HandedOut | None, robot: str, to: str, term: int, move_id: str) -> str:
    """Why a source does not give ``robot`` to sim ``to`` (``''``: it does): it handed out no such robot, or not to
    that sim, not in that move, or not at that term."""
    if kept is None:
        return f"no robot {robot} was handed out here"
    if kept.to != to:
        return f"robot {robot} was handed out to sim {kept.to}, not to sim {to}"
    if kept.move != move_id:
        return f"robot {robot} was handed out in another move"
    if kept.handoff.term != int(term):
        return f"robot {robot} was handed out at term {kept.handoff.term}, not {term}"
    return ""


def take_back_refusal(kept: HandedOut | None, robot: str, move_id: str | None, target_live: bool) -> str:
    """Why a source does not serve ``robot`` again (``''``: it does). ``move_id`` None: the source's own timer,
    which names no move. A robot the target fetched is taken back only once the target gave it back or is gone:
    it may serve it, and two sims serving one robot is the clone the move must never make."""
    if kept is None:
        return f"no robot {robot} was handed out here"
    if move_id is not None and kept.move != move_id:
        return f"robot {robot} was handed out in another move"
    if kept.fetched and target_live:
        return f"sim {kept.to} took robot {robot} (it fetched it and did not give it back): ask sim {kept.to}"
    return ""


def check_handoff(h: Handoff, robot: str, source: str, term: int) -> None:
    """What a target checks in the handoff it fetched: the robot asked for, from the sim asked, at the move's term
    (:class:`MoveError` naming what disagrees)."""
    if h.state.id != robot or h.placement.id != robot or (h.record is not None and h.record.object != robot):
        raise MoveError(f"sim {source} handed out another robot than {robot}")
    if h.source != source:
        raise MoveError(f"the handoff of {robot} comes from sim {h.source or '?'}, not from sim {source}")
    if int(h.term) != int(term):
        raise MoveError(f"robot {robot} was handed out at term {h.term}, not at the move's term {term}")


def step(
    kind: str,
    robot: str,
    *,
    to: str = "",
    source: str = "",
    term: int = 0,
    move_id: str = "",
    rtype: str = "",
    asker: str = "",
    decline: bool = False,
) -> Event:
    """One step of a move as a ``srv/move`` query or answer (no handoff in it: see :func:`to_event`)."""
    data: dict[str, Any] = {"to": to, "from": source, "term": int(term), "move": move_id}
    if rtype:
        data["type"] = rtype
    if decline:
        data["decline"] = True
    return Event(kind=kind, reason="move", object=robot, data=data, header=Header(wall_ns=time.time_ns(), source=asker))


def move_term(source_term: int, target_term: int) -> int:
    """The term both sims serve under after a move: above both, so the target's word on the robot is believed
    (consumers' fences, the ownership client) and the source's on its other robots still is."""
    return max(int(source_term), int(target_term)) + 1


def merge_records(
    records: tuple[OwnershipRecord, ...], add: OwnershipRecord | None = None, drop: str = ""
) -> tuple[OwnershipRecord, ...]:
    """A sim's exported records with ``drop``'s left out and ``add`` put in (replacing one of its object)."""
    out = [r for r in records if r.object != drop and (add is None or r.object != add.object)]
    if add is not None:
        out.append(add)
    return tuple(sorted(out, key=lambda r: r.object))


def named_users(users: Mapping[str, Any], record: OwnershipRecord | None) -> dict[str, Any]:
    """The entries of an exported users map about the users ``record`` names (owner and queue)."""
    if record is None:
        return {}
    names = {record.owner, *record.queue} - {""}
    return {k: v for k, v in users.items() if str(k).partition(":")[2] in names}


def merge_users(users: Mapping[str, Any], moved: Mapping[str, Any]) -> dict[str, Any]:
    """The target's exported users with the moved record's users added: one it did not rank yet ranks after its
    own (join order is each authority's), its liveness and absence as the source knew them."""
    out = dict(users)
    nxt = int(out.get("next_rank", 0))
    for key in sorted(
        moved, key=lambda k: (not str(k).startswith("rank:"), moved[k] if str(k).startswith("rank:") else 0, str(k))
    ):
        kind, _, user = str(key).partition(":")
        if kind == "rank":
            if f"rank:{user}" not in out:
                out[f"rank:{user}"] = nxt
                nxt += 1
        elif (
            key not in out
            and not (kind == "away" and f"live:{user}" in out)
            and not (kind == "live" and f"away:{user}" in out)
        ):
            out[key] = moved[key]
    out["next_rank"] = nxt
    return out


def to_event(
    kind: str, robot: str, to: str, handoff: Handoff | None = None, *, term: int = 0, source: str = ""
) -> Event:
    """The ``srv/state`` query (or answer) of one step of a move. A handoff travels as a one-robot
    :class:`~fabric.interfaces.WorldState` (its state, its record, its users, its sequence numbers), encoded in
    ``data["handoff"]`` (an event's data holds scalars only), its placement beside it."""
    data: dict[str, Any] = {"to": to, "term": int(term)}
    if handoff is not None:
        ws = WorldState(
            0.0,
            0,
            (handoff.state,),
            (),
            (handoff.record,) if handoff.record is not None else (),
            dict(handoff.users),
            {str(k): int(v) for k, v in handoff.seqs.items()},
            header=Header(source=handoff.source, term=int(handoff.term)),
        )
        p = handoff.placement
        data.update(handoff=base64.b64encode(encode(ws)).decode("ascii"), type=p.type, pose=[float(v) for v in p.pose])
    return Event(
        kind=kind, reason="move", object=robot, data=data, header=Header(wall_ns=time.time_ns(), source=source)
    )


def from_event(ev: Event) -> Handoff:
    """The handoff an event carries; raises :class:`MoveError` when it carries none (or a broken one)."""
    d = ev.data if isinstance(ev.data, dict) else {}
    try:
        ws = decode(base64.b64decode(str(d["handoff"]), validate=True), WorldState)
        (state,) = ws.robots
        record = ws.records[0] if ws.records else None
        pose = tuple(float(v) for v in d["pose"])
        if (
            state.id != ev.object
            or (record is not None and record.object != ev.object)
            or len(ws.records) > 1
            or len(pose) != 4
        ):
            raise ValueError("the robot's state, record and id disagree")
        return Handoff(
            state,
            SceneRobot(str(d["type"]), ev.object, pose),
            record,
            dict(ws.users),
            dict(ws.seqs),
            ws.header.term,
            ws.header.source,
        )
    except Exception as exc:
        raise MoveError(f"no robot handed out in this move: {exc}") from None


def ask(fabric: Any, sim: str, login: str, request: Event, timeout: float) -> Event:
    """Ask sim ``sim`` one step of a move on ``srv/move/{sim}/by/{login}``; its answer, taken as soon as it comes.
    :class:`MoveError` with its refusal; :class:`NoAnswer` when nothing came within ``timeout``."""
    from fabric import keys
    from fabric.interfaces import NoReply, Refused

    try:
        return fabric.rpc.first(keys.srv_move(fabric.world, sim, login), request, timeout=timeout, expected=Event)
    except Refused as exc:
        raise MoveError(exc.reason) from None
    except NoReply:
        raise NoAnswer(
            f"sim {sim} did not answer the {request.kind} step of {request.object} within {timeout:.0f} s"
        ) from None


def move(fabric: Any, robot: str, to: str, *, timeout: float = 10.0) -> dict[str, Any]:
    """Move ``robot`` to sim ``to`` (the tool's side): ask the world's sims for their terms, the robot's sim to hand
    it out, the target to take it in (and, should the target refuse, the source to take it back), each on
    ``srv/move/{sim}/by/{login}``. Returns ``{"robot", "from", "to", "term", "pause_ms"}``; raises
    :class:`MoveError` with the refusing sim's reason (or the router's refusal of this login)."""
    from fabric import keys
    from fabric.interfaces import ServiceError, WorldInfo

    try:
        parts = fabric.rpc.query(keys.srv(fabric.world, "world"), timeout=2.0, expected=WorldInfo, all_replies=True)
    except ServiceError as exc:
        raise MoveError(f"no sim describes world {fabric.world!r}: {exc}") from None
    terms = {r.source: r.message.header.term for r in parts}
    source = next((r.source for r in parts if any(x.id == robot for x in r.message.robots)), "")
    if not source:
        raise MoveError(f"no sim of world {fabric.world!r} serves robot {robot!r}")
    if source == to:
        raise MoveError(f"robot {robot} is already served by sim {to}")
    if to not in terms:
        raise MoveError(f"sim {to} does not serve world {fabric.world!r} (sims: {', '.join(sorted(terms))})")
    term = move_term(terms[source], terms[to])
    login = fabric.config.identity() or fabric.peer_id

    def ask_(sim: str, request: Event, wait: float) -> Event:
        return ask(fabric, sim, login, request, wait)

    try:
        ask_(source, step(MOVE_CHECK, robot, to=to, source=source, term=term, asker=fabric.peer_id), CHECK_TIMEOUT_S)
    except NoAnswer:
        raise MoveError(
            f"sim {source} did not answer on srv/move/{source}/by/{login} within {CHECK_TIMEOUT_S:.0f} s: moving "
            f"robots is for the instructor and sim logins (a class's router refuses login {login!r} there), or "
            f"sim {source} is older than this tool"
        ) from None
    t0 = time.monotonic()
    out = ask_(source, step(MOVE_OUT, robot, to=to, source=source, term=term, asker=fabric.peer_id), timeout)
    move_id = str(out.data.get("move", "")) if isinstance(out.data, dict) else ""
    try:
        ask_(to, step(MOVE_IN, robot, to=to, source=source, term=term, move_id=move_id, asker=fabric.peer_id), timeout)
    except MoveError as exc:
        try:  # the source takes it back, as it kept it
            ask_(
                source,
                step(MOVE_IN, robot, to=source, source=source, term=term, move_id=move_id, asker=fabric.peer_id),
                timeout,
            )
        except MoveError as back:
            raise MoveError(
                f"sim {to} refused {robot} ({exc}) and sim {source} did not take it back ({back}); sim {source} "
                f"takes it back by itself within {RETURN_AFTER_S:.0f} s if sim {to} never fetched it"
            ) from None
        raise MoveError(f"sim {to} refused {robot}: {exc}; it stays with sim {source}") from None
    return {"robot": robot, "from": source, "to": to, "term": term, "pause_ms": (time.monotonic() - t0) * 1000.0}
