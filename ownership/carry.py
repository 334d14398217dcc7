"""Carrying ownership records forward at a take-over: a snapshot's records overlaid with the newer ones heard since.

A standby restores the ownership state from its leader's last ``srv/state`` snapshot, asked for every poll period
(:mod:`sim_peer.replica.following`). A grant, a release or a queue change the leader made after that snapshot was published
on ``own/{object}`` but is not in it: restoring the snapshot alone would lose it, and the new authority would
publish an older epoch than the one owners and replicas already hold (the soak saw arm1's epoch go back 516 ->
515 when the primary's cable was cut 36 ms after a grant). So the standby keeps the newest record of each object
its leader published, and :func:`overlay` puts the ones published after the snapshot over the snapshot's. Pure:
records in, records out; an epoch never goes back.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Iterable, Mapping

from fabric.interfaces import OwnershipRecord

__all__ = ["overlay", "newer", "changed_hands"]


def newer(heard: OwnershipRecord, snapshot: OwnershipRecord | None, next_seq: int) -> bool:
    """Whether ``heard`` (a record its authority published) comes after the snapshot that holds ``snapshot`` for its
    object, whose authority's next sequence number on the record's key was ``next_seq`` when it was taken: a higher
    epoch (epochs only grow), or the same epoch published at or after that sequence number (a queue or motion change).
    A lower epoch never is."""
    if snapshot is None:
        return True
    if heard.epoch != snapshot.epoch:
        return heard.epoch > snapshot.epoch
    return heard.header.seq >= next_seq


def overlay(
    records: Iterable[OwnershipRecord],
    users: Mapping[str, Any],
    heard: Iterable[OwnershipRecord],
    next_seqs: Mapping[str, int] | None = None,
) -> tuple[tuple[OwnershipRecord, ...], dict[str, Any]]:
    """The snapshot's ``records`` and ``users`` (as :func:`ownership.snapshot.export` wrote them) with every ``heard``
    record that is :func:`newer` put in its object's place. ``next_seqs``: object -> the snapshot's next sequence number
    on its record's key (none known: 0, any record of the same epoch is taken).

    A record taken here has its lease reset (``lease_expiry`` 0: the restore gives its owner a whole lease, as it gives
    every owner). Its owner and the users in its queue that the snapshot's users do not know (a first request granted
    after the snapshot) are ranked after the others and counted live, as the old authority had them; the new authority
    asks their tokens to confirm it within a lease of hearing again (:class:`ownership.hearing.Hearing`)."""
    seqs = next_seqs or {}
    out = {r.object: r for r in records}
    new_users = dict(users)
    rank = int(
        new_users.get(
            "next_rank", 1 + max((int(v) for k, v in users.items() if str(k).startswith("rank:")), default=-1)
        )
    )
    for rec in sorted(heard, key=lambda r: r.object):
        if not newer(rec, out.get(rec.object), int(seqs.get(rec.object, 0))):
            continue
        out[rec.object] = replace(rec, lease_expiry=0.0)
        for user in (rec.owner, *rec.queue):
            if user and f"rank:{user}" not in new_users:
                new_users[f"rank:{user}"] = rank
                rank += 1
            if user and f"away:{user}" not in new_users:
                new_users[f"live:{user}"] = True
    new_users["next_rank"] = rank
    return tuple(out[o] for o in sorted(out)), new_users


def changed_hands(snapshot: Iterable[OwnershipRecord], restored: Iterable[OwnershipRecord]) -> tuple[str, ...]:
    """The objects whose owner or epoch the ``restored`` records (:func:`overlay`'s) moved on from the ``snapshot``'s:
    their leader stopped each of them when it lost its owner there (``CommandQueue.on_owner_lost``), after the
    snapshot that carries their controllers, so a take-over must stop them again. Without it a standby drove an arm
    on to its former owner's target with nobody owning it (the soak's ``unowned_motion``: arm0 moved 4.0 s after its
    owner went, on the sim that took over)."""
    before = {r.object: (r.owner, r.epoch) for r in snapshot}
    return tuple(r.object for r in restored if before.get(r.object, ("", 0)) != (r.owner, r.epoch))
