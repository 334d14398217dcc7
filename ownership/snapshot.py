"""Moving the ownership state from one authority to another: pure export and restore.

A primary exports its :class:`~ownership.state.OwnState` with every time *relative* to its own
clock's ``now`` (remaining lease, remaining grace), because the standby that restores it runs
another clock (another process, maybe another machine). The standby rebases them on its ``now``.

What is kept: every record (owner, epoch, queue, motion state), the users' join order, who was
live, who is away within grace and what they held, who requested without a token yet, and when the
authority last heard a user, started hearing again and ticked (the lease rule's memory). Owners keep
their objects and their epochs, so the commands they stamp stay valid. A lease resumes with what
remained of it, but never less than one full lease: while no authority answered, an owner could
not renew, and losing a robot to the failover itself is what this exists to prevent.
"""

from __future__ import annotations

from dataclasses import replace
from types import MappingProxyType
from typing import Any, Mapping, TypedDict

from fabric.interfaces import OwnershipRecord

from ownership import state as st

__all__ = ["export", "restore"]


def export(s: st.OwnState, now: float) -> tuple[tuple[OwnershipRecord, ...], dict[str, Any]]:
    """Records (``lease_expiry`` as seconds remaining) and the users' state as a flat map of plain values."""
    recs = tuple(
        replace(r, lease_expiry=max(0.0, r.lease_expiry - now) if r.owner else 0.0)
        for _, r in sorted(s.records.items())
    )
    users: dict[str, Any] = {"next_rank": s.next_rank}
    for u, rank in s.rank.items():
        users[f"rank:{u}"] = rank
    for u in s.live:
        users[f"live:{u}"] = True
    for u, a in s.away.items():
        users[f"away:{u}"] = [
            a.deadline - now,
            *(f"o:{o}" for o in sorted(a.owned)),
            *(f"q:{o}" for o in sorted(a.queued)),
        ]
    for u, d in s.unproven.items():
        users[f"unproven:{u}"] = d - now  # may be past: the next tick drops it, as it would have
    for u, t in s.held.items():
        users[f"held:{u}"] = t - now  # her token went while hearing was in doubt: grace counts from then
    # what the lease rule knows of the authority's hearing and its own pauses (never heard / never ticked: None),
    # so the restored authority judges a lease exactly as the old one would have
    users["clock"] = [
        None if t == float("-inf") else t - now for t in (s.heard, s.hearing_since, s.last_tick, s.regained)
    ]
    return recs, users


def restore(
    records: tuple[OwnershipRecord, ...] | list[OwnershipRecord],
    users: Mapping[str, Any],
    now: float,
    *,
    lease_s: float,
    grace_s: float,
    authority: str,
) -> st.OwnState:
    """The state :func:`export` described, on this authority's clock at ``now``; records name ``authority``."""
    recs = {}
    for r in records:
        expiry = now + max(float(r.lease_expiry), lease_s) if r.owner else 0.0
        recs[r.object] = replace(r, lease_expiry=expiry, authority=authority)
    rank: dict[str, int] = {}
    live: set[str] = set()
    away: dict[str, st.Away] = {}
    unproven: dict[str, float] = {}
    held: dict[str, float] = {}
    for key, value in users.items():
        kind, _, user = str(key).partition(":")
        if kind == "rank":
            rank[user] = int(value)
        elif kind == "live":
            live.add(user)
        elif kind == "away":
            vals = list(value)
            owned = frozenset(v[2:] for v in vals[1:] if str(v).startswith("o:") and v[2:] in recs)
            queued = frozenset(v[2:] for v in vals[1:] if str(v).startswith("q:") and v[2:] in recs)
            away[user] = st.Away(now + float(vals[0]), owned, queued)
        elif kind == "unproven":
            unproven[user] = now + float(value)
        elif kind == "held":
            held[user] = now + float(value)
    return st.OwnState(
        records=MappingProxyType(recs),
        rank=MappingProxyType(rank),
        live=frozenset(live),
        away=MappingProxyType(away),
        next_rank=int(users.get("next_rank", max(rank.values(), default=-1) + 1)),
        unproven=MappingProxyType(unproven),
        held=MappingProxyType({u: t for u, t in held.items() if u in live}),
        lease_s=lease_s,
        grace_s=grace_s,
        authority=authority,
        deaf_s=lease_s / 2,
        **_clock(users.get("clock"), now),
    )


class _Clock(TypedDict):
    heard: float
    hearing_since: float
    last_tick: float
    regained: float


def _clock(value: Any, now: float) -> _Clock:
    """``heard``, ``hearing_since``, ``last_tick`` and ``regained`` on this clock, from :func:`export`'s relative
    times; an export without them (an older authority) leaves them unknown, as a fresh authority has them."""
    vals = list(value) if isinstance(value, (list, tuple)) and len(value) in (3, 4) else []
    vals += [None] * (4 - len(vals))
    t = [float("-inf") if v is None else now + float(v) for v in vals]
    return _Clock(heard=t[0], hearing_since=t[1], last_tick=t[2], regained=t[3])
