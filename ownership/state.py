"""Pure ownership state machine: events in, (new state, effects) out.

No zenoh and no clock: ``now`` arrives inside the events, so the same code runs
in the authority and in hypothesis property tests. Records are
:class:`fabric.interfaces.OwnershipRecord` (the replicated wire record).

Rules (DESIGN.md, issue 5):
- ``exclusive`` objects have at most one owner, always a live user; ``scene``
  objects are never owned (anyone writes, last writer wins).
- The owner's epoch (fencing token) increases on every change of owner.
- Waiting users are kept sorted by *join order* (the order users first joined
  the world), so a user reconnecting within grace returns to its old place.
- A request on a still robot hands it over at once; on a moving one it is
  denied (or queued when the requester asks to wait). A release, lease expiry
  or owner departure passes ownership to the head of the queue.
- Bounded against made-up users (issue 14): a queue holds at most
  :data:`fabric.interfaces.MAX_QUEUE` users, and a user that requested without a
  liveliness token (a :class:`Join`) is dropped, from queues and ownership, once
  ``grace_s`` has passed without one: forged requesters leave on their own. Until its
  token is seen such a user may take a free robot but never take one over from its owner
  (a flood of forged requests took a still robot from its owner a thousand times in a row).
  At most :data:`MAX_UNPROVEN` such users are held at once; a request from one more is
  denied before anything is copied or kept, so a flood of forged names costs each request
  the same small work (every step copies these maps, and an unbounded one made 20k forged
  requests quadratic: ~28 s under the authority's lock, long enough to expire real leases).
  ``rank`` and ``live`` hold only users with a token (or away within grace) and these.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Mapping

from fabric.interfaces import MAX_QUEUE, OwnershipRecord

__all__ = [
    "Effect", "OwnState", "Join", "Leave", "Request", "Release", "Renew", "Tick", "Motion",
    "initial", "step", "MAX_UNPROVEN",
]

MAX_UNPROVEN = 256
"""Requesters without a liveliness token held at once; more are refused until grace drops some."""


@dataclass(frozen=True, slots=True)
class Join:
    user: str
    now: float


@dataclass(frozen=True, slots=True)
class Leave:
    user: str
    now: float


@dataclass(frozen=True, slots=True)
class Request:
    user: str
    object: str
    now: float
    wait: bool = False


@dataclass(frozen=True, slots=True)
class Release:
    user: str
    object: str
    now: float = 0.0


@dataclass(frozen=True, slots=True)
class Renew:
    user: str
    object: str
    now: float


@dataclass(frozen=True, slots=True)
class Tick:
    now: float


@dataclass(frozen=True, slots=True)
class Motion:
    object: str
    moving: bool


Event = Join | Leave | Request | Release | Renew | Tick | Motion


@dataclass(frozen=True, slots=True)
class Effect:
    """What happened: ``kind`` is granted|denied|queued|released|handover|expired|revoked|restored|renewed."""

    kind: str
    object: str = ""
    user: str = ""
    reason: str = ""
    position: int = 0


@dataclass(frozen=True, slots=True)
class Away:
    """A user whose token went: its join rank and the objects it held or waited for, until ``deadline``."""

    deadline: float
    owned: frozenset[str]
    queued: frozenset[str]


@dataclass(frozen=True, slots=True)
class OwnState:
    records: Mapping[str, OwnershipRecord]
    rank: Mapping[str, int] = field(default_factory=dict)  # user -> join rank (live or away)
    live: frozenset[str] = frozenset()
    away: Mapping[str, Away] = field(default_factory=dict)
    next_rank: int = 0
    unproven: Mapping[str, float] = field(default_factory=dict)  # user -> deadline for its token (requested without one)
    lease_s: float = 2.0
    grace_s: float = 10.0
    authority: str = ""


def initial(objects: Mapping[str, str], *, lease_s: float = 2.0, grace_s: float = 10.0, authority: str = "") -> OwnState:
    recs = {}
    for obj, policy in objects.items():
        if policy not in ("scene", "exclusive"):
            raise ValueError(f"object {obj!r}: policy must be scene or exclusive, not {policy!r}")
        recs[obj] = OwnershipRecord(object=obj, policy=policy, authority=authority)
    return OwnState(records=MappingProxyType(recs), lease_s=lease_s, grace_s=grace_s, authority=authority)


# ---------------------------------------------------------------------- helpers

def _sorted_queue(s: OwnState, users) -> tuple[str, ...]:
    return tuple(sorted(set(users), key=lambda u: (s.rank.get(u, 1 << 60), u)))


def _with(s: OwnState, recs: dict, **kw) -> OwnState:
    return replace(s, records=MappingProxyType(recs), **kw)


def _join(s: OwnState, user: str) -> OwnState:
    if user in s.live:
        return s
    rank = dict(s.rank)
    nxt = s.next_rank
    if user not in rank:
        rank[user] = nxt
        nxt += 1
    return replace(s, rank=MappingProxyType(rank), live=s.live | {user}, next_rank=nxt)


def _pass_on(s: OwnState, rec: OwnershipRecord, now: float, effects: list, why: str) -> OwnershipRecord:
    """The owner goes (``why``): the head of the live queue owns next, else the object is free."""
    queue = [u for u in rec.queue if u in s.live]
    if queue:
        nxt = queue.pop(0)
        effects.append(Effect("handover", rec.object, nxt, f"{why} by {rec.owner}" if rec.owner else why))
        return replace(rec, owner=nxt, epoch=rec.epoch + 1, lease_expiry=now + s.lease_s, queue=tuple(queue))
    effects.append(Effect("released", rec.object, rec.owner, why))
    return replace(rec, owner="", epoch=rec.epoch + 1, lease_expiry=0.0, queue=tuple(queue))


def _drop_unproven(s: OwnState, recs: dict, user: str, now: float, effects: list) -> OwnState:
    """``user`` requested without a liveliness token and none came within grace: it leaves everything
    (no grace to come back: it never was there), and nothing is kept about it."""
    for obj, rec in list(recs.items()):
        if rec.owner == user:
            recs[obj] = _pass_on(replace(s, live=s.live - {user}), rec, now, effects, "no liveliness token")
        elif user in rec.queue:
            recs[obj] = replace(rec, queue=tuple(u for u in rec.queue if u != user))
            effects.append(Effect("released", obj, user, "left the queue: no liveliness token"))
    return replace(
        s,
        live=s.live - {user},
        rank=MappingProxyType({k: v for k, v in s.rank.items() if k != user}),
        unproven=MappingProxyType({k: v for k, v in s.unproven.items() if k != user}),
    )


# ---------------------------------------------------------------------- step

def step(s: OwnState, ev: Event) -> tuple[OwnState, list[Effect]]:
    """Apply one event; never raises for a well-typed event on a known object."""
    effects: list[Effect] = []
    recs = dict(s.records)

    if isinstance(ev, Join):
        was_away = s.away.get(ev.user)
        if ev.user in s.unproven:
            s = replace(s, unproven=MappingProxyType({k: v for k, v in s.unproven.items() if k != ev.user}))
        s = _join(s, ev.user)
        if was_away is not None and ev.now <= was_away.deadline:
            away = {k: v for k, v in s.away.items() if k != ev.user}
            s = replace(s, away=MappingProxyType(away))
            for obj in sorted(was_away.owned | was_away.queued):
                rec = recs[obj]
                if not rec.owner and obj in was_away.owned:
                    recs[obj] = replace(rec, owner=ev.user, epoch=rec.epoch + 1, lease_expiry=ev.now + s.lease_s)
                    effects.append(Effect("restored", obj, ev.user, "owner again"))
                elif rec.owner != ev.user:
                    q = _sorted_queue(s, rec.queue + (ev.user,))
                    recs[obj] = replace(rec, queue=q)
                    effects.append(Effect("restored", obj, ev.user, "queued", q.index(ev.user) + 1))
            return _with(s, recs), effects
        if was_away is not None:  # grace over: a new join rank
            away = {k: v for k, v in s.away.items() if k != ev.user}
            rank = {k: v for k, v in s.rank.items() if k != ev.user}
            s = replace(s, away=MappingProxyType(away), rank=MappingProxyType(rank), live=s.live - {ev.user})
            s = _join(s, ev.user)
        return s, effects

    if isinstance(ev, Leave):
        if ev.user not in s.live:
            return s, effects
        s = replace(s, live=s.live - {ev.user}, unproven=MappingProxyType({k: v for k, v in s.unproven.items() if k != ev.user}))
        owned, queued = set(), set()
        for obj, rec in list(recs.items()):
            if rec.owner == ev.user:
                owned.add(obj)
                recs[obj] = _pass_on(s, rec, ev.now, effects, "left")
            elif ev.user in rec.queue:
                queued.add(obj)
                recs[obj] = replace(rec, queue=tuple(u for u in rec.queue if u != ev.user))
        away = dict(s.away)
        away[ev.user] = Away(ev.now + s.grace_s, frozenset(owned), frozenset(queued))
        return _with(s, recs, away=MappingProxyType(away)), effects

    if isinstance(ev, Tick):
        for obj, rec in list(recs.items()):
            if rec.owner and ev.now > rec.lease_expiry:
                recs[obj] = _pass_on(s, rec, ev.now, effects, "lease expired")
                effects.append(Effect("expired", obj, rec.owner, "lease expired"))
        for user in [u for u, d in s.unproven.items() if ev.now > d]:
            s = _drop_unproven(s, recs, user, ev.now, effects)
        gone = [u for u, a in s.away.items() if ev.now > a.deadline]
        if gone:
            away = {k: v for k, v in s.away.items() if k not in gone}
            rank = {k: v for k, v in s.rank.items() if k not in gone}
            s = replace(s, away=MappingProxyType(away), rank=MappingProxyType(rank))
        return _with(s, recs), effects

    if isinstance(ev, Motion):
        rec = recs[ev.object]
        state = "moving" if ev.moving else "still"
        if rec.state != state:
            recs[ev.object] = replace(rec, state=state)
        return _with(s, recs), effects

    rec = recs.get(ev.object)
    if rec is None:
        effects.append(Effect("denied", ev.object, ev.user, f"unknown object {ev.object!r}"))
        return s, effects

    if isinstance(ev, Request):
        if ev.user not in s.live and len(s.unproven) >= MAX_UNPROVEN:  # checked before anything is copied
            effects.append(Effect("denied", rec.object, ev.user, f"too many requesters without a liveliness token "
                                  f"({MAX_UNPROVEN}); connect with a fabric session and ask again"))
            return s, effects
        if ev.user not in s.live:  # a request proves the user is there, until grace runs out without its token
            s = replace(s, unproven=MappingProxyType({**s.unproven, ev.user: ev.now + s.grace_s}))
        s = _join(s, ev.user)
        if rec.policy == "scene":
            effects.append(Effect("granted", rec.object, ev.user, "scene object: anyone writes"))
            return s, effects
        if rec.owner == ev.user:
            recs[rec.object] = replace(rec, lease_expiry=ev.now + s.lease_s)
            effects.append(Effect("granted", rec.object, ev.user, "already owner"))
            return _with(s, recs), effects
        if rec.owner and ev.user in s.unproven:  # no token seen yet: it may take a free robot, never someone's
            if ev.wait and ev.user not in rec.queue and len(rec.queue) < MAX_QUEUE:
                q = _sorted_queue(s, rec.queue + (ev.user,))
                recs[rec.object] = replace(rec, queue=q)
                effects.append(Effect("queued", rec.object, ev.user, f"owned by {rec.owner}; no liveliness token seen yet",
                                      q.index(ev.user) + 1))
                return _with(s, recs), effects
            full = ev.wait and ev.user not in rec.queue
            why = f"the queue is full ({MAX_QUEUE} waiting)" if full else f"owned by {rec.owner}; no liveliness token seen yet"
            effects.append(Effect("denied", rec.object, ev.user, why))
            return s, effects
        if not rec.owner or rec.state == "still":
            prev = rec.owner
            queue = tuple(u for u in rec.queue if u != ev.user)
            recs[rec.object] = replace(rec, owner=ev.user, epoch=rec.epoch + 1, lease_expiry=ev.now + s.lease_s, queue=queue)
            effects.append(Effect("granted", rec.object, ev.user, f"taken over from {prev} (still)" if prev else "free"))
            if prev:
                effects.append(Effect("revoked", rec.object, prev, f"handed over to {ev.user} while still"))
            return _with(s, recs), effects
        if ev.wait and ev.user not in rec.queue and len(rec.queue) >= MAX_QUEUE:
            effects.append(Effect("denied", rec.object, ev.user, f"the queue is full ({MAX_QUEUE} waiting)"))
            return s, effects
        if ev.wait:
            q = _sorted_queue(s, rec.queue + (ev.user,))
            recs[rec.object] = replace(rec, queue=q)
            effects.append(Effect("queued", rec.object, ev.user, f"in motion, owned by {rec.owner}", q.index(ev.user) + 1))
            return _with(s, recs), effects
        effects.append(Effect("denied", rec.object, ev.user, f"in motion, owned by {rec.owner}"))
        return s, effects

    if isinstance(ev, Release):
        if rec.owner == ev.user:
            recs[rec.object] = _pass_on(s, rec, ev.now, effects, "released")
        elif ev.user in rec.queue:
            recs[rec.object] = replace(rec, queue=tuple(u for u in rec.queue if u != ev.user))
            effects.append(Effect("released", rec.object, ev.user, "left the queue"))
        else:
            effects.append(Effect("denied", rec.object, ev.user, f"not the owner ({rec.owner or 'free'})"))
        return _with(s, recs), effects

    if isinstance(ev, Renew):
        if rec.owner == ev.user:
            recs[rec.object] = replace(rec, lease_expiry=ev.now + s.lease_s)
            effects.append(Effect("renewed", rec.object, ev.user))
            return _with(s, recs), effects
        away = s.away.get(ev.user)
        if (not rec.owner and away is not None and rec.object in away.owned and ev.now <= away.deadline
                and len(s.unproven) < MAX_UNPROVEN):
            # Her token went (a router restart closes every link) and her renewal is back before it: the
            # renewal proves she is there, as a request does, so she gets back what she held, as her
            # token's return would give it. Left to the token, the renewal was denied, her client stopped
            # renewing, and a restore it then missed expired a lease later (router loss, issue 15).
            s = replace(s, unproven=MappingProxyType({**s.unproven, ev.user: ev.now + s.grace_s}))
            s = _join(s, ev.user)
            recs[rec.object] = replace(rec, owner=ev.user, epoch=rec.epoch + 1, lease_expiry=ev.now + s.lease_s,
                                       queue=tuple(u for u in rec.queue if u != ev.user))
            effects.append(Effect("restored", rec.object, ev.user, "owner again: renewed within grace"))
            return _with(s, recs), effects
        effects.append(Effect("denied", rec.object, ev.user, f"not the owner ({rec.owner or 'free'})"))
        return s, effects

    raise TypeError(f"not an ownership event: {ev!r}")
