"""Who is a world's sim authority: a pure election and fencing core.

One primary serves the world; any number of standbys follow it. Each sim peer runs this state
machine on what it observes, events in, (new state, effects) out, no clock and no zenoh, so the
same code runs in the peer and in hypothesis property tests.

Rules:

- The term only grows. A primary stamps its term on everything it writes.
- A standby follows the source of the highest term it has heard (``Heard``).
- When the primary's liveliness token is not among the live ones (``Peers``: a complete view, the
  caller's job; a liveliness history still arriving is not one), the standby with the lowest id
  among the live standbys takes over with ``term + 1``; the others wait. If that one dies too, the
  next ``Peers`` makes the next lowest take over. Deterministic: every standby that sees the same
  set of live peers agrees on one candidate.
- A primary that hears a higher term steps down and becomes a standby of its source; one that hears
  its own term from another peer (two standbys disagreed about who was alive) keeps authority only
  if its id is the lower: the pair converges on one authority without talking. A standby settles
  the same tie the same way, unless the lower one's token is gone (it died, and a standby that
  never heard its term took over with the same one).
- State with a lower term than the highest heard is ignored (effect ``ignore``).
- Elections are per **shard** (docs/sim.md, "Several sims, one world"): several sims may serve one world,
  each the authority of its own robots. A sim's election hears only its own robots' terms (the caller
  filters ``Heard``) and counts only the sims of its shard (:func:`shard_view`): the sims that serve or
  follow a robot of its own, and those not asked yet (one world, one shard: what every sim did before).
- A leader still *heard* (its term on a stream or ``srv/state`` within the last moment: ``Peers.audible``) is
  alive, whatever the liveliness view says: a sim whose own link just came back (paused past the lease, a
  router restarted) can see the tokens late, and a standby that took over then would serve a world that stops
  where its state does, while the leader it follows serves on (the soak saw a primary, just stepped down,
  take the world back at once with epochs older than its leader's).
- A primary back from a freeze longer than the lease that finds no higher term (``Resumed``) goes on
  under term + 1 (effect ``reassert``): a standby that took over and died meanwhile may have had
  consumers fence at that term. (If several did, one after the other, and all died before the old
  primary came back, consumers that heard the last of them ignore it: docs/sim.md, limits.)
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable

__all__ = [
    "Role",
    "Election",
    "Heard",
    "Peers",
    "Resumed",
    "ElectionEffect",
    "candidate",
    "shard_view",
    "start",
    "step",
    "PRIMARY",
    "STANDBY",
]

PRIMARY = "primary"
STANDBY = "standby"
Role = str


@dataclass(frozen=True, slots=True)
class Election:
    """What one sim peer believes: its role, the highest term heard (its own when primary), who leads."""

    me: str
    role: Role
    term: int = 0
    leader: str = ""
    # the leader's liveliness token was seen alive since we follow it: until then its absence from a view says nothing
    # of its death (the shell counts such a leader, still heard, as audible: sim_peer.replica.roles.Roles.audible)
    leader_seen: bool = False
    live: frozenset[str] = frozenset()  # the live sim peers as last reported (``Peers``)


@dataclass(frozen=True, slots=True)
class Heard:
    """Authority state from ``source`` stamped with ``term``."""

    source: str
    term: int


@dataclass(frozen=True, slots=True)
class Peers:
    """The sim peers whose liveliness tokens are alive now (this one included or not: it is added)."""

    live: frozenset[str]
    audible: frozenset[str] = frozenset()
    """The sims heard just now (their stamped state arrived within the last moment): alive, token or not."""


@dataclass(frozen=True, slots=True)
class Resumed:
    """This peer was frozen longer than the lease (its token was dropped) and found no higher term."""


Event = Heard | Peers | Resumed


@dataclass(frozen=True, slots=True)
class ElectionEffect:
    """``take_over`` (serve the world with ``term``), ``step_down`` (stop serving, follow ``leader``),
    ``follow`` (a new leader to follow), ``ignore`` (stale state: do not use it)."""

    kind: str
    term: int = 0
    leader: str = ""


def candidate(standbys: Iterable[str]) -> str | None:
    """The standby that takes over: the lowest id (plain string order), None when there is none."""
    return min(standbys, default=None)


def shard_view(live: Iterable[str], shards: dict[str, frozenset[str]], me: str, mine: frozenset[str]) -> frozenset[str]:
    """The live sims of ``me``'s shard: those whose robots (``shards``: what each said it serves or follows)
    meet ``mine``, those not asked yet, and ``me``."""
    return frozenset(p for p in live if p == me or p not in shards or shards[p] & mine)


def start(me: str, *, standby: bool, term: int = 0) -> Election:
    """A primary starts at ``term`` (>= 1 on the wire: 0 means 'no authority'); a standby knows nothing yet."""
    if standby:
        return Election(me, STANDBY, 0, "")
    return Election(me, PRIMARY, max(1, term), me)


def step(s: Election, ev: Event) -> tuple[Election, list[ElectionEffect]]:
    """Apply one observation."""
    if isinstance(ev, Heard):
        if ev.source == s.me:
            return s, []
        if ev.term < s.term:
            return s, [ElectionEffect("ignore", ev.term, ev.source)]
        if s.role == PRIMARY:
            if ev.term > s.term or (ev.term == s.term and ev.source < s.me):
                s = replace(s, role=STANDBY, term=ev.term, leader=ev.source)
                return s, [ElectionEffect("step_down", ev.term, ev.source)]
            return s, [ElectionEffect("ignore", ev.term, ev.source)]  # same term, higher id: it steps down, not us
        if ev.term > s.term or ev.source != s.leader:
            if ev.term == s.term and s.leader and ev.source > s.leader and s.leader in s.live:
                # the same tie, seen from a standby; but a leader whose token went is no tie: a standby that
                # never heard the dead one's term takes over with the same term, and must be followed
                return s, [ElectionEffect("ignore", ev.term, ev.source)]
            seen = (s.leader_seen and ev.source == s.leader) or ev.source in s.live
            s = replace(s, term=ev.term, leader=ev.source, leader_seen=seen)
            return s, [ElectionEffect("follow", ev.term, ev.source)]
        return s, []
    if isinstance(ev, Peers):
        s = replace(s, live=frozenset(ev.live))
        if s.role == PRIMARY or not s.leader:
            return s, []  # nothing to take over: we lead, or follow nobody yet
        if s.leader in ev.live:
            return (s if s.leader_seen else replace(s, leader_seen=True)), []
        if s.leader in ev.audible:
            return s, []  # its token is late, not gone: it still speaks
        standbys = set(ev.live) | {s.me}
        if candidate(standbys) != s.me:
            return s, []
        s = replace(s, role=PRIMARY, term=s.term + 1, leader=s.me)
        return s, [ElectionEffect("take_over", s.term, s.me)]
    if isinstance(ev, Resumed):
        if s.role != PRIMARY:
            return s, []
        # a standby may have taken over and died meanwhile, its term heard by consumers but not by us:
        # come back under a new term, so whoever fenced at that one takes us again
        s = replace(s, term=s.term + 1)
        return s, [ElectionEffect("reassert", s.term, s.me)]
    raise TypeError(f"not an election event: {ev!r}")
