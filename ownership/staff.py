"""An instructor's actions on the ownership state: pure, like :mod:`ownership.state` (events in, effects out).

Instructors act through the authority's rules as staff, never around them (docs/design.md): each action is
one :class:`Staff` event the authority applies under its lock, so the records, epochs, queues and stops
follow the same rules as a student's release, and every change is published and logged as an event:

- ``take_back``: the owner loses the robot as on her release (it stops; the next live user in the queue owns
  it, else it is free);
- ``give``: the robot goes to ``to`` (a live user), whoever held it, moving or not (the former owner's robot
  stops first); ``to`` leaves its queue;
- ``lock``: the owner loses it (it stops), and nobody may request it until ``unlock`` (the record's
  ``locked`` names the instructor); a locked robot is restored to nobody;
- ``unlock``: requests are taken again; the head of the live queue owns it at once;
- ``stop`` and ``reset``: the robot stops (or goes back to its start), its owner keeps it.

Who may act as staff is the router's to say (``own/{obj}/staff/by/{login}`` is open to the instructor
logins alone in a class's rules, robofabric.secure); this module checks what an action needs of the state.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from fabric.interfaces import STAFF_OPS, OwnershipRecord

from ownership import state as st

__all__ = ["Staff", "step", "STAFF_OPS"]


@dataclass(frozen=True, slots=True)
class Staff:
    """Instructor ``staff`` does ``op`` (:data:`STAFF_OPS`) on ``object`` at ``now``; ``to``: whom a give is for."""

    staff: str
    object: str
    op: str
    now: float
    to: str = ""


def step(s: st.OwnState, ev: Staff | st.Event) -> tuple[st.OwnState, list[st.Effect]]:
    """:func:`ownership.state.step`, and a :class:`Staff` event. Effects as there, plus ``done`` (what the instructor
    is answered, and what the authority logs as an ``own_staff`` event) or ``denied`` (why not), and ``reset``
    (the sim puts the robot back at its start)."""
    if not isinstance(ev, Staff):
        return st.step(s, ev)
    effects: list[st.Effect] = []
    rec = s.records.get(ev.object)
    why = _refusal(s, rec, ev)
    if why:
        return s, [st.Effect("denied", ev.object, ev.staff, why)]
    assert rec is not None
    by = f"instructor {ev.staff}"
    if ev.op == "stop":
        if rec.owner:
            effects.append(st.Effect("stop", rec.object, rec.owner, f"stopped by {by}"))
        return s, effects + [st.Effect("done", rec.object, ev.staff, f"{rec.object} stopped by {by}")]
    if ev.op == "reset":
        return s, [
            st.Effect("reset", rec.object, rec.owner, f"reset by {by}"),
            st.Effect("done", rec.object, ev.staff, f"{rec.object} reset by {by}"),
        ]
    if ev.op == "give":
        new = _give(s, rec, ev, by, effects)
    elif ev.op == "take_back":
        new = _pass(s, rec, ev.now, effects, f"taken back by {by}")
    elif ev.op == "lock":
        new = replace(_pass(s, rec, ev.now, effects, f"locked by {by}", nobody=True), locked=ev.staff)
    else:  # unlock
        new = _pass(s, replace(rec, locked=""), ev.now, effects, f"unlocked by {by}")
    effects.append(st.Effect("done", rec.object, ev.staff, _done(rec, new, ev, by)))
    return st._with(s, {**s.records, rec.object: new}), effects


def _refusal(s: st.OwnState, rec: OwnershipRecord | None, ev: Staff) -> str:
    """Why this action cannot be done ('' when it can), in words for the instructor."""
    if ev.op not in STAFF_OPS:
        return f"not a staff action: {ev.op!r} (one of {', '.join(STAFF_OPS)})"
    if rec is None:
        return f"unknown object {ev.object!r}"
    if rec.policy == "scene":
        return f"{rec.object} is a scene object: anyone moves it, nobody owns it"
    if ev.op == "take_back" and not rec.owner:
        return f"{rec.object} is free: nobody to take it back from"
    if ev.op == "give":
        if ev.to not in s.live:
            return f"{ev.to or 'nobody'} is not logged in: a robot goes only to a user who is there"
        if rec.locked:
            return f"{rec.object} is locked: unlock it first"
        if rec.owner == ev.to:
            return f"{ev.to} owns {rec.object} already"
    if ev.op == "lock" and rec.locked:
        return f"{rec.object} is locked already (by instructor {rec.locked})"
    if ev.op == "unlock" and not rec.locked:
        return f"{rec.object} is not locked"
    return ""


def _pass(
    s: st.OwnState, rec: OwnershipRecord, now: float, effects: list[st.Effect], why: str, *, nobody: bool = False
) -> OwnershipRecord:
    """The owner (if any) loses ``rec``, which stops; the head of the live queue owns it next (unless ``nobody``:
    a lock keeps the queue, to be served at the unlock), else it is free. The epoch moves on."""
    queue = [u for u in rec.queue if u in s.live]
    if rec.owner:
        effects.append(st.Effect("revoked", rec.object, rec.owner, why))
        effects.append(st.Effect("stop", rec.object, rec.owner, f"{rec.owner}: {why}"))
    if queue and not nobody:
        nxt = queue.pop(0)
        effects.append(st.Effect("handover", rec.object, nxt, why))
        return replace(rec, owner=nxt, epoch=rec.epoch + 1, lease_expiry=now + s.lease_s, queue=tuple(queue))
    if rec.owner:
        effects.append(st.Effect("released", rec.object, rec.owner, why))
    return replace(
        rec, owner="", epoch=rec.epoch + 1, lease_expiry=0.0, queue=tuple(queue) if not nobody else rec.queue
    )


def _give(s: st.OwnState, rec: OwnershipRecord, ev: Staff, by: str, effects: list[st.Effect]) -> OwnershipRecord:
    why = f"given to {ev.to} by {by}"
    if rec.owner:
        effects.append(st.Effect("revoked", rec.object, rec.owner, why))
        effects.append(st.Effect("stop", rec.object, rec.owner, f"{rec.owner}: {why}"))
    effects.append(st.Effect("handover", rec.object, ev.to, why))
    queue = tuple(u for u in rec.queue if u != ev.to)
    return replace(rec, owner=ev.to, epoch=rec.epoch + 1, lease_expiry=ev.now + s.lease_s, queue=queue)


def _done(before: OwnershipRecord, after: OwnershipRecord, ev: Staff, by: str) -> str:
    """What the instructor is told (and the class's event log says) an action did."""
    owner = f"now {after.owner}'s" if after.owner else "now free"
    if ev.op == "give":
        return f"{after.object} given to {ev.to} by {by}" + (f" (from {before.owner})" if before.owner else "")
    if ev.op == "take_back":
        return f"{after.object} taken back from {before.owner} by {by}: {owner}"
    if ev.op == "lock":
        return f"{after.object} locked by {by}" + (f" (taken from {before.owner})" if before.owner else "")
    return f"{after.object} unlocked by {by}: {owner}"
