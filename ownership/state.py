"""Pure ownership state machine: events in, (new state, effects) out.

No zenoh and no clock: ``now`` arrives inside the events, so the same code runs
in the authority and in hypothesis property tests. Records are
:class:`fabric.interfaces.OwnershipRecord` (the replicated wire record).

Rules (docs/design.md):
- ``exclusive`` objects have at most one owner, always a live user; ``scene``
  objects are never owned (anyone writes, last writer wins).
- The owner's epoch (fencing token) increases on every change of owner.
- Waiting users are kept sorted by *join order* (the order users first joined
  the world), so a user reconnecting within grace returns to its old place.
- A request on a still robot hands it over at once; on a moving one it is
  denied (or queued when the requester asks to wait). A release, lease expiry
  or owner departure passes ownership to the head of the queue.
- The authority's own trouble is never an owner's fault: a lease expires only when its owner's
  renewals stopped while the authority was hearing others (:func:`may_expire`). Nothing heard
  from anyone for ``deaf_s`` (a stalled router, a backlog, a lost link) or a late tick (the
  authority paused) stops expiries, and once it hears again every owner has a whole lease to renew; so does
  its own link's loss or return, however short (renewals sent meanwhile went with the old link).
- Likewise a token lost while the authority's hearing is in doubt (:func:`hearing_in_doubt`: it heard
  nobody for ``deaf_s`` although another owner should have renewed, or heard again after such a deaf
  spell less than ``grace_s`` ago) is not taken as its user leaving: a
  stalled router cuts its clients' links and drops their tokens (20,000 declarations at once, or the
  router paused 8 s, released and restored owners' robots). The user is *held*: she keeps what she
  owns (her lease does not run out) and her queue places, with no record changed, until her token
  comes back (nothing happened) or ``grace_s`` passes without it (then she leaves, as on a token loss).
- A robot moves only while a live owner drives it: every change of owner away from a user (her
  release, a handover, a take-over, her lease's end, her departure) comes with a ``stop`` effect
  naming the former owner and why; the authority hands it to the sim, which stops the robot.
- Bounded against made-up users: a queue holds at most
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
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from fabric.interfaces import MAX_QUEUE, OwnershipRecord

__all__ = [
    "Effect",
    "OwnState",
    "Join",
    "Leave",
    "Request",
    "Release",
    "Renew",
    "Tick",
    "Motion",
    "initial",
    "step",
    "may_expire",
    "hearing_in_doubt",
    "MAX_UNPROVEN",
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
    relinked: bool = False
    """The authority's own link to its router was lost or came back since the last tick: renewals sent to it
    meanwhile went with the old link, so every owner gets a whole lease to renew from ``now``."""


@dataclass(frozen=True, slots=True)
class Motion:
    object: str
    moving: bool


Event = Join | Leave | Request | Release | Renew | Tick | Motion


@dataclass(frozen=True, slots=True)
class Effect:
    """What happened: ``kind`` is granted|denied|queued|released|handover|expired|revoked|restored|renewed|stop.

    ``stop``: the robot lost its owner ``user`` (``reason`` says how) and must stop (docs/design.md: a robot
    moves only while a live owner drives it); it is applied by the sim, never by this module."""

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
    unproven: Mapping[str, float] = field(
        default_factory=dict
    )  # user -> deadline for its token (requested without one)
    lease_s: float = 2.0
    grace_s: float = 10.0
    authority: str = ""
    deaf_s: float = 1.0  # nothing heard from any user for longer: the authority (or its router) is deaf
    heard: float = float("-inf")  # when the last request, release, renewal or token reached the authority
    hearing_since: float = float("-inf")  # when it last started hearing again after a silence or its own pause
    last_tick: float = float("-inf")
    regained: float = float(
        "-inf"
    )  # when it last heard again after a silence of deaf_s or its own pause (not the first time)
    held: Mapping[str, float] = field(default_factory=dict)  # user -> when her token went while hearing was in doubt
    plant: str = ""  # a defect planted for the soak's checker (fabric/plant.py); "" in every real world


def initial(
    objects: Mapping[str, str],
    *,
    lease_s: float = 2.0,
    grace_s: float = 10.0,
    authority: str = "",
    deaf_s: float | None = None,
    plant: str = "",
) -> OwnState:
    recs = {}
    for obj, policy in objects.items():
        if policy not in ("scene", "exclusive"):
            raise ValueError(f"object {obj!r}: policy must be scene or exclusive, not {policy!r}")
        recs[obj] = OwnershipRecord(object=obj, policy=policy, authority=authority)
    return OwnState(
        records=MappingProxyType(recs),
        lease_s=lease_s,
        grace_s=grace_s,
        authority=authority,
        deaf_s=deaf_s if deaf_s is not None else lease_s / 2,
        plant=plant,
    )


# ---------------------------------------------------------------------- helpers


def _sorted_queue(s: OwnState, users: Iterable[str]) -> tuple[str, ...]:
    return tuple(sorted(set(users), key=lambda u: (s.rank.get(u, 1 << 60), u)))


def _with(s: OwnState, recs: dict[str, OwnershipRecord], **kw: Any) -> OwnState:
    out = replace(s, records=MappingProxyType(recs), **kw)
    return _forfeit_taken(out, s.records) if out.away else out


def _forfeit_taken(s: OwnState, before: Mapping[str, OwnershipRecord]) -> OwnState:
    """An object someone else came to own while its former owner was away is no longer hers to get back:
    she was not there while another user moved it, so her program must hear that she lost it (a record
    naming the other owner, or a free one of a newer epoch) rather than find herself owner again."""
    taken = {
        obj
        for obj, rec in s.records.items()
        if rec.owner and (before.get(obj) is None or before[obj].owner != rec.owner)
    }
    if not taken:
        return s
    away = {}
    for user, a in s.away.items():
        lost = {o for o in a.owned & taken if s.records[o].owner != user}
        away[user] = replace(a, owned=a.owned - lost, queued=a.queued | lost) if lost else a  # her place behind, kept
    return replace(s, away=MappingProxyType(away))


def _join(s: OwnState, user: str) -> OwnState:
    if user in s.live:
        return s
    rank = dict(s.rank)
    nxt = s.next_rank
    if user not in rank:
        rank[user] = nxt
        nxt += 1
    return replace(s, rank=MappingProxyType(rank), live=s.live | {user}, next_rank=nxt)


def _pass_on(s: OwnState, rec: OwnershipRecord, now: float, effects: list[Effect], why: str) -> OwnershipRecord:
    """The owner goes (``why``): the head of the live queue owns next, else the object is free; the robot stops."""
    queue = [u for u in rec.queue if u in s.live]
    if queue:
        nxt = queue.pop(0)
        effects.append(Effect("handover", rec.object, nxt, f"{why} by {rec.owner}" if rec.owner else why))
        out = replace(rec, owner=nxt, epoch=rec.epoch + 1, lease_expiry=now + s.lease_s, queue=tuple(queue))
    else:
        effects.append(Effect("released", rec.object, rec.owner, why))
        out = replace(rec, owner="", epoch=rec.epoch + 1, lease_expiry=0.0, queue=tuple(queue))
    if rec.owner:
        effects.append(Effect("stop", rec.object, rec.owner, _stop_reason(rec.owner, why)))
    return out


def _stop_reason(owner: str, why: str) -> str:
    """Why a robot stops, in words: ``released by alice``, ``alice left``, ``lease of ... expired ...``."""
    if why == "released":
        return f"released by {owner}"
    if why == "left":
        return f"{owner} left"
    return f"{owner}: {why}" if owner not in why else why


def _drop_unproven(
    s: OwnState, recs: dict[str, OwnershipRecord], user: str, now: float, effects: list[Effect]
) -> OwnState:
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
        held=MappingProxyType({k: v for k, v in s.held.items() if k != user}),
    )


# ---------------------------------------------------------------------- hearing


def _hear(s: OwnState, now: float) -> OwnState:
    """Something from a user reached the authority at ``now`` (a request, release, renewal or token):
    after a silence longer than ``deaf_s`` the authority starts hearing again from ``now``."""
    since = s.hearing_since if now - s.heard <= s.deaf_s else now
    if s.heard >= now and since == s.hearing_since:
        return s
    regained = now if since == now and s.heard != float("-inf") and _overdue(s, now) else s.regained
    return replace(s, heard=max(s.heard, now), hearing_since=since, regained=regained)


def _overdue(s: OwnState, now: float, but: str = "") -> bool:
    """Whether an owner other than ``but`` has not been heard for ``deaf_s`` (owners renew several times a lease)."""
    return any(
        rec.owner and rec.owner != but and now - (rec.lease_expiry - s.lease_s) > s.deaf_s for rec in s.records.values()
    )


def hearing_in_doubt(s: OwnState, now: float, user: str = "") -> bool:
    """Whether ``user``'s token lost at ``now`` may be the authority's (or its router's) trouble rather than her
    leaving: nobody was heard for ``deaf_s`` although another owner should have renewed, or the authority heard
    again after such a deaf spell (or its own pause) less than ``grace_s`` ago, while the links its router cut
    meanwhile are still being closed and reopened. An owner alone going quiet is not doubt: her cable pulled,
    her renewals stop and her token goes a transport lease later, with nobody else to hear."""
    silent = s.heard != float("-inf") and now - s.heard > s.deaf_s and _overdue(s, now, but=user)
    return silent or now <= s.regained + s.grace_s


def may_expire(s: OwnState, rec: OwnershipRecord, now: float) -> bool:
    """Whether ``rec``'s lease may end at ``now``: it ran out, the authority has been hearing users
    (nothing from anyone for ``deaf_s`` means the authority, or its router, is the deaf one), and the
    owner had a whole lease to renew since the authority hears again (after its own pause or a backlog,
    renewals sent meanwhile are still on their way)."""
    return (
        bool(rec.owner)
        and now > rec.lease_expiry
        and now - s.heard <= s.deaf_s
        and now > s.hearing_since + s.lease_s
        and rec.owner not in s.held
    )


# ---------------------------------------------------------------------- step


def step(s: OwnState, ev: Event) -> tuple[OwnState, list[Effect]]:
    """Apply one event; never raises for a well-typed event on a known object."""
    handler = _HANDLERS.get(type(ev))
    if handler is None:
        raise TypeError(f"not an ownership event: {ev!r}")
    effects: list[Effect] = []
    if isinstance(ev, (Join, Request, Release, Renew)):
        s = _hear(s, ev.now)
    return handler(s, ev, effects), effects


def _on_join(s: OwnState, ev: Join, effects: list[Effect]) -> OwnState:
    """A user's token appeared: a new join rank, or its old place back within grace."""
    if ev.user in s.held:  # her token went while the authority could not tell why, and is back: nothing happened
        s = replace(s, held=MappingProxyType({k: v for k, v in s.held.items() if k != ev.user}))
    was_away = s.away.get(ev.user)
    if ev.user in s.unproven:
        s = replace(s, unproven=MappingProxyType({k: v for k, v in s.unproven.items() if k != ev.user}))
    s = _join(s, ev.user)
    if was_away is None:
        return s
    away = {k: v for k, v in s.away.items() if k != ev.user}
    if ev.now > was_away.deadline:  # grace over: a new join rank
        rank = {k: v for k, v in s.rank.items() if k != ev.user}
        s = replace(s, away=MappingProxyType(away), rank=MappingProxyType(rank), live=s.live - {ev.user})
        return _join(s, ev.user)
    s = replace(s, away=MappingProxyType(away))
    recs = dict(s.records)
    for obj in sorted(was_away.owned | was_away.queued):
        rec = recs[obj]
        if not rec.owner and obj in was_away.owned and not rec.locked:
            recs[obj] = replace(rec, owner=ev.user, epoch=rec.epoch + 1, lease_expiry=ev.now + s.lease_s)
            effects.append(Effect("restored", obj, ev.user, "owner again"))
        elif rec.owner and rec.owner != ev.user:  # behind whoever owns it now (a free robot she may request)
            q = _sorted_queue(s, rec.queue + (ev.user,))
            recs[obj] = replace(rec, queue=q)
            effects.append(Effect("restored", obj, ev.user, "queued", q.index(ev.user) + 1))
    return _with(s, recs)


def _on_leave(s: OwnState, ev: Leave, effects: list[Effect]) -> OwnState:
    """A user's token went: what it owned passes on, its queue places go; grace keeps them for its return.
    While the authority's hearing is in doubt (:func:`hearing_in_doubt`) she is held instead: nothing changes."""
    if ev.user not in s.live or ev.user in s.held:
        return s
    if hearing_in_doubt(s, ev.now, ev.user):
        return replace(s, held=MappingProxyType({**s.held, ev.user: ev.now}))
    return _leave(s, ev.user, ev.now, effects)


def _leave(s: OwnState, user: str, now: float, effects: list[Effect]) -> OwnState:
    """``user`` is gone: what she owned passes on, her queue places go; grace keeps them for her return."""
    ev = Leave(user, now)
    s = replace(
        s,
        live=s.live - {ev.user},
        unproven=MappingProxyType({k: v for k, v in s.unproven.items() if k != ev.user}),
        held=MappingProxyType({k: v for k, v in s.held.items() if k != ev.user}),
    )
    recs = dict(s.records)
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
    return _with(s, recs, away=MappingProxyType(away))


def _on_tick(s: OwnState, ev: Tick, effects: list[Effect]) -> OwnState:
    """Time passes: leases that may end (:func:`may_expire`) end, tokenless requesters and away users past
    grace are forgotten, held users whose token did not come back within grace leave. A tick long after the
    last one means the authority itself was paused: it hears again from now, so every owner gets a whole
    lease to renew; so does a tick that says the authority's own link was lost or came back."""
    if s.last_tick != float("-inf") and ev.now - s.last_tick > s.deaf_s:
        s = replace(s, hearing_since=max(s.hearing_since, ev.now), regained=max(s.regained, ev.now))
    elif ev.relinked:
        # a class's starved sim lost its link for 0.0 s and, a second after it was back, expired 24 leases whose
        # renewals had gone with the old link ("no renewal for 2.0 s": `bench console --clients 32`, 2026-12-02)
        s = replace(s, hearing_since=max(s.hearing_since, ev.now))
    s = replace(s, last_tick=ev.now)
    recs = dict(s.records)
    for obj, rec in list(recs.items()):
        if may_expire(s, rec, ev.now):
            quiet = ev.now - (rec.lease_expiry - s.lease_s)
            why = f"lease of {obj} ({rec.owner}) expired: no renewal for {quiet:.1f} s"
            recs[obj] = _pass_on(s, rec, ev.now, effects, why)
            effects.append(Effect("expired", obj, rec.owner, why))
    for user in [u for u, d in s.unproven.items() if ev.now > d]:
        s = _drop_unproven(s, recs, user, ev.now, effects)
    for user in [u for u, t in s.held.items() if ev.now > t + s.grace_s]:  # her token never came back: she left
        s = _leave(_with(s, recs), user, ev.now, effects)
        recs = dict(s.records)
    gone = [u for u, a in s.away.items() if ev.now > a.deadline]
    if gone:
        away = {k: v for k, v in s.away.items() if k not in gone}
        # a user who asked again while away (a request before her token came back) is live: her place stays
        rank = {k: v for k, v in s.rank.items() if k not in gone or k in s.live}
        s = replace(s, away=MappingProxyType(away), rank=MappingProxyType(rank))
    return _with(s, recs)


def _on_motion(s: OwnState, ev: Motion, effects: list[Effect]) -> OwnState:
    rec = s.records[ev.object]
    state = "moving" if ev.moving else "still"
    if rec.state == state:
        return s
    return _with(s, {**s.records, ev.object: replace(rec, state=state)})


def _unknown(s: OwnState, ev: Request | Release | Renew, effects: list[Effect]) -> bool:
    if ev.object in s.records:
        return False
    effects.append(Effect("denied", ev.object, ev.user, f"unknown object {ev.object!r}"))
    return True


def _on_request(s: OwnState, ev: Request, effects: list[Effect]) -> OwnState:
    """Granted when free or still (a take-over), queued or denied while it moves; tokenless users only get free robots."""
    if _unknown(s, ev, effects):
        return s
    rec = s.records[ev.object]
    if ev.user not in s.live and len(s.unproven) >= MAX_UNPROVEN:  # checked before anything is copied
        effects.append(
            Effect(
                "denied",
                rec.object,
                ev.user,
                f"too many requesters without a liveliness token "
                f"({MAX_UNPROVEN}); connect with a fabric session and ask again",
            )
        )
        return s
    if ev.user not in s.live:  # a request proves the user is there, until grace runs out without its token
        s = replace(s, unproven=MappingProxyType({**s.unproven, ev.user: ev.now + s.grace_s}))
    s = _join(s, ev.user)
    recs = dict(s.records)
    if rec.policy == "scene":
        effects.append(Effect("granted", rec.object, ev.user, "scene object: anyone writes"))
        return s
    if rec.locked:  # an instructor locked it (ownership.staff)
        effects.append(
            Effect("denied", rec.object, ev.user, f"locked by instructor {rec.locked}: ask them to unlock it")
        )
        return s
    if rec.owner == ev.user:
        recs[rec.object] = replace(rec, lease_expiry=ev.now + s.lease_s)
        effects.append(Effect("granted", rec.object, ev.user, "already owner"))
        return _with(s, recs)
    if rec.owner and ev.user in s.unproven:  # no token seen yet: it may take a free robot, never someone's
        if ev.wait and ev.user not in rec.queue and len(rec.queue) < MAX_QUEUE:
            q = _sorted_queue(s, rec.queue + (ev.user,))
            recs[rec.object] = replace(rec, queue=q)
            effects.append(
                Effect(
                    "queued",
                    rec.object,
                    ev.user,
                    f"owned by {rec.owner}; no liveliness token seen yet",
                    q.index(ev.user) + 1,
                )
            )
            return _with(s, recs)
        full = ev.wait and ev.user not in rec.queue
        why = (
            f"the queue is full ({MAX_QUEUE} waiting)"
            if full
            else f"owned by {rec.owner}; no liveliness token seen yet"
        )
        effects.append(Effect("denied", rec.object, ev.user, why))
        return s
    if not rec.owner or rec.state == "still":
        prev = rec.owner
        queue = tuple(u for u in rec.queue if u != ev.user)
        bump = (
            0 if prev and s.plant == "double-owner" else 1
        )  # test-only defect (fabric/plant.py); 1 in every real world
        recs[rec.object] = replace(
            rec, owner=ev.user, epoch=rec.epoch + bump, lease_expiry=ev.now + s.lease_s, queue=queue
        )
        effects.append(Effect("granted", rec.object, ev.user, f"taken over from {prev} (still)" if prev else "free"))
        if prev:
            effects.append(Effect("revoked", rec.object, prev, f"handed over to {ev.user} while still"))
            effects.append(Effect("stop", rec.object, prev, f"taken over by {ev.user} from {prev}"))
        return _with(s, recs)
    if ev.wait and ev.user not in rec.queue and len(rec.queue) >= MAX_QUEUE:
        effects.append(Effect("denied", rec.object, ev.user, f"the queue is full ({MAX_QUEUE} waiting)"))
        return s
    if ev.wait:
        q = _sorted_queue(s, rec.queue + (ev.user,))
        recs[rec.object] = replace(rec, queue=q)
        effects.append(Effect("queued", rec.object, ev.user, f"in motion, owned by {rec.owner}", q.index(ev.user) + 1))
        return _with(s, recs)
    effects.append(Effect("denied", rec.object, ev.user, f"in motion, owned by {rec.owner}"))
    return s


def _on_release(s: OwnState, ev: Release, effects: list[Effect]) -> OwnState:
    """The owner lets go (the next in the queue owns it), or a waiting user leaves the queue."""
    if _unknown(s, ev, effects):
        return s
    rec = s.records[ev.object]
    if rec.owner == ev.user:
        return _with(s, {**s.records, rec.object: _pass_on(s, rec, ev.now, effects, "released")})
    if ev.user in rec.queue:
        effects.append(Effect("released", rec.object, ev.user, "left the queue"))
        return _with(s, {**s.records, rec.object: replace(rec, queue=tuple(u for u in rec.queue if u != ev.user))})
    effects.append(Effect("denied", rec.object, ev.user, f"not the owner ({rec.owner or 'free'})"))
    return s


def _on_renew(s: OwnState, ev: Renew, effects: list[Effect]) -> OwnState:
    """The owner's lease starts again; an owner away within grace whose robot is still free gets it back."""
    if _unknown(s, ev, effects):
        return s
    rec = s.records[ev.object]
    if rec.owner == ev.user:
        effects.append(Effect("renewed", rec.object, ev.user))
        return _with(s, {**s.records, rec.object: replace(rec, lease_expiry=ev.now + s.lease_s)})
    away = s.away.get(ev.user)
    if (
        not rec.owner
        and not rec.locked
        and away is not None
        and rec.object in away.owned
        and ev.now <= away.deadline
        and len(s.unproven) < MAX_UNPROVEN
    ):
        # Her token went (a router restart closes every link) and her renewal is back before it: the
        # renewal proves she is there, as a request does, so she gets back what she held, as her
        # token's return would give it; denied, her client would stop renewing and lose the robot.
        s = replace(s, unproven=MappingProxyType({**s.unproven, ev.user: ev.now + s.grace_s}))
        s = _join(s, ev.user)
        back = replace(
            rec,
            owner=ev.user,
            epoch=rec.epoch + 1,
            lease_expiry=ev.now + s.lease_s,
            queue=tuple(u for u in rec.queue if u != ev.user),
        )
        effects.append(Effect("restored", rec.object, ev.user, "owner again: renewed within grace"))
        return _with(s, {**s.records, rec.object: back})
    effects.append(Effect("denied", rec.object, ev.user, f"not the owner ({rec.owner or 'free'})"))
    return s


_HANDLERS: dict[type, Callable[[OwnState, Any, list[Effect]], OwnState]] = {
    Join: _on_join,
    Leave: _on_leave,
    Tick: _on_tick,
    Motion: _on_motion,
    Request: _on_request,
    Release: _on_release,
    Renew: _on_renew,
}
