"""Moving a robot from one sim of a world to another (docs/sim.md, "Moving a robot between sims").

A compiled MuJoCo model cannot gain or lose bodies, so a move is two rebuilds on the standby's take-over path
(:meth:`sim_peer.standby.ReplicaHost._serve`): the source stops serving, hands out the robot's state, its
placement, its ownership record and its streams' sequence numbers (a :class:`Handoff`) and goes on without it;
the target builds its world again with the robot added, restores every robot (its own from its world, the moved
one from the handoff) and serves it with its ownership record, so the owner keeps it and her epoch.

The operator's tool (:func:`move`, ``robofabric own move``) drives the three steps through ``srv/state``
(``Event(kind="move_out" | "move_in")``), so no sim waits on another inside a query: both sims first raise
their term to ``max(source, target) + 1``: consumers' fences and ownership clients follow a robot's authority by
its term, and a record of the same term from another sim would be refused while the old sim is alive.

Pure helpers here; the tool's I/O is :func:`move`.
"""

from __future__ import annotations

import base64
import time
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

from fabric.codec import DecodeError, decode, encode
from fabric.interfaces import Event, Header, OwnershipRecord, RobotState, WorldState
from robots.description import SceneRobot

__all__ = ["MOVE_OUT", "MOVE_IN", "Handoff", "MoveError", "move_term", "merge_records", "merge_users",
           "to_event", "from_event", "move"]

MOVE_OUT = "move_out"
"""``Event.kind`` of a ``srv/state`` query asking the robot's sim to stop serving it and hand it out."""
MOVE_IN = "move_in"
"""``Event.kind`` of a ``srv/state`` query asking a sim to serve a handed-out robot (or, on failure, its source to
take it back)."""


class MoveError(Exception):
    """A move that could not be made; the reason names what refused it."""


@dataclass(frozen=True, slots=True)
class Handoff:
    """What a sim hands out with a robot: its controller state, its placement (type, id, spawn pose, where the
    target builds it, so a ``reset`` still sends it home), its ownership record (None without ownership), the users that record names (join ranks,
    liveness, as :func:`ownership.replica.export` writes them), its streams' next sequence numbers, and the term
    both sims serve under after the move."""

    state: RobotState
    placement: SceneRobot
    record: OwnershipRecord | None
    users: Mapping[str, Any] = field(default_factory=dict)
    seqs: Mapping[str, int] = field(default_factory=dict)
    term: int = 0
    source: str = ""


def move_term(source_term: int, target_term: int) -> int:
    """The term both sims serve under after a move: above both, so the target's word on the robot is believed
    (consumers' fences, the ownership client) and the source's on its other robots still is."""
    return max(int(source_term), int(target_term)) + 1


def merge_records(records: tuple[OwnershipRecord, ...], add: OwnershipRecord | None = None, drop: str = "") -> tuple[OwnershipRecord, ...]:
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
    for key in sorted(moved, key=lambda k: (not str(k).startswith("rank:"), moved[k] if str(k).startswith("rank:") else 0, str(k))):
        kind, _, user = str(key).partition(":")
        if kind == "rank":
            if f"rank:{user}" not in out:
                out[f"rank:{user}"] = nxt
                nxt += 1
        elif key not in out and not (kind == "away" and f"live:{user}" in out) and not (kind == "live" and f"away:{user}" in out):
            out[key] = moved[key]
    out["next_rank"] = nxt
    return out


def to_event(kind: str, robot: str, to: str, handoff: Handoff | None = None, *, term: int = 0, source: str = "") -> Event:
    """The ``srv/state`` query (or answer) of one step of a move. A handoff travels as a one-robot
    :class:`~fabric.interfaces.WorldState` (its state, its record, its users, its sequence numbers), encoded in
    ``data["handoff"]`` (an event's data holds scalars only), its placement beside it."""
    data: dict[str, Any] = {"to": to, "term": int(term)}
    if handoff is not None:
        ws = WorldState(0.0, 0, (handoff.state,), (), (handoff.record,) if handoff.record is not None else (), dict(handoff.users),
                        {str(k): int(v) for k, v in handoff.seqs.items()}, header=Header(source=handoff.source, term=int(handoff.term)))
        p = handoff.placement
        data.update(handoff=base64.b64encode(encode(ws)).decode("ascii"), type=p.type, pose=[float(v) for v in p.pose])
    return Event(kind=kind, reason="move", object=robot, data=data, header=Header(wall_ns=time.time_ns(), source=source))


def from_event(ev: Event) -> Handoff:
    """The handoff an event carries; raises :class:`MoveError` when it carries none (or a broken one)."""
    d = ev.data if isinstance(ev.data, dict) else {}
    try:
        ws = decode(base64.b64decode(str(d["handoff"]), validate=True), WorldState)
        (state,) = ws.robots
        record = ws.records[0] if ws.records else None
        pose = tuple(float(v) for v in d["pose"])
        if state.id != ev.object or (record is not None and record.object != ev.object) or len(ws.records) > 1 or len(pose) != 4:
            raise ValueError("the robot's state, record and id disagree")
        return Handoff(state, SceneRobot(str(d["type"]), ev.object, pose), record, dict(ws.users), dict(ws.seqs), ws.header.term,
                       ws.header.source)
    except Exception as exc:
        raise MoveError(f"no robot handed out in this move: {exc}") from None


def move(fabric: Any, robot: str, to: str, *, timeout: float = 10.0) -> dict[str, Any]:
    """Move ``robot`` to sim ``to`` (the tool's side): ask the world's sims for their terms, the robot's sim to hand
    it out, the target to take it in (and, should the target refuse, the source to take it back). Returns
    ``{"robot", "from", "to", "term", "pause_ms"}``; raises :class:`MoveError` with the refusing sim's reason."""
    from fabric import keys
    from fabric.interfaces import ServiceError, WorldInfo

    srv = keys.srv(fabric.world, "state")
    try:
        parts = fabric.query(keys.srv(fabric.world, "world"), timeout=2.0, expected=WorldInfo, all_replies=True)
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
    t0 = time.monotonic()

    def ask(kind: str, handoff: Handoff | None, at: str) -> Event:
        """The answer of the one sim the step is for (the others do not answer): taken as soon as it comes, so a
        sim slow to close the query does not hold the move up."""
        import zenoh

        errors: list[str] = []
        request = encode(to_event(kind, robot, at, handoff, term=term, source=fabric.peer_id))
        for rep in fabric.session.get(srv, payload=request, timeout=timeout, target=zenoh.QueryTarget.ALL,
                                      consolidation=zenoh.ConsolidationMode.NONE):
            try:
                if rep.ok is not None:
                    return decode(rep.ok.payload.to_bytes(), Event)
                errors.append(decode(rep.err.payload.to_bytes(), Event).reason)
            except DecodeError as exc:
                errors.append(f"bad reply: {exc}")
        raise MoveError(errors[0] if errors else f"no sim answered the {kind} step of {robot} within {timeout:.0f} s")

    out = ask(MOVE_OUT, None, to)
    handoff = from_event(out)
    try:
        ask(MOVE_IN, handoff, to)
    except MoveError as exc:
        try:
            ask(MOVE_IN, handoff, source)  # the source takes it back, as it was
        except MoveError as back:
            raise MoveError(f"sim {to} refused {robot} ({exc}) and sim {source} did not take it back ({back}): "
                            f"restart {source} with it") from None
        raise MoveError(f"sim {to} refused {robot}: {exc}; it stays with sim {source}") from None
    return {"robot": robot, "from": source, "to": to, "term": term, "pause_ms": (time.monotonic() - t0) * 1000.0}
