"""What a primary does after a freeze, before it publishes again: a pure core.

:class:`sim_peer.replica.freeze_guard.FreezeGuard` is called back by the fabric's freeze watch with the gap between two of
its publications (it is muzzled meanwhile); it passes the gap, the lease and the sims that could have taken over
(:func:`rivals`) to :func:`plan`, and carries out the :class:`FreezePlan` it gets. No zenoh, no lock, no clock.

The rules:

- with no other sim of its shard alive when the freeze began (alive now, or whose token went since), nothing could
  have taken over: publish again at once;
- otherwise ask ``srv/state`` who holds the shard now (for :func:`ask_for` seconds at most, once connected) and step
  down if a higher term answers; after a gap longer than the lease (the others dropped our token, and our session
  may not even know yet that its link died), first listen muzzled for a lease and half a second: a new authority's
  streams reach us once the session is back, and hearing its higher term steps us down before anything goes out;
- still the authority after that: publish again, and after a gap longer than the lease go on under a new term
  (:class:`sim_peer.replica.election.Resumed`): a standby that took over and died meanwhile may have had consumers fence at
  its term.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["FreezePlan", "plan", "rivals", "began", "watch_gap", "ask_for", "LISTEN_MARGIN_S", "ASK_MIN_S"]

LISTEN_MARGIN_S = 0.5
"""Listened beyond the lease after a freeze longer than it (the new authority's first samples in flight)."""
ASK_MIN_S = 30.0
"""The least time given to asking who holds the shard once connected (a reconnecting session can be slow)."""


@dataclass(frozen=True, slots=True)
class FreezePlan:
    """What to do after a freeze: publish again at once (``publish_now``: nobody could have taken over), or listen
    muzzled ``listen_s`` seconds, ask who holds the shard, and, if still the authority, publish again under a new
    term when ``reassert``."""

    publish_now: bool
    listen_s: float = 0.0
    reassert: bool = False


def watch_gap(lease: float) -> float:
    """The publication gap that counts as a freeze by default: half the lease, so that a freeze long enough for the
    others to drop our token is always caught, with margin (a false alarm, a starved process, costs one query)."""
    return lease / 2


def began(now: float, gap: float) -> float:
    """When a freeze of ``gap`` seconds reported at ``now`` began."""
    return now - gap


def rivals(shard_sims: Iterable[str], me: str) -> frozenset[str]:
    """The sims that could have taken this sim's shard over: those of its shard alive when the freeze began or since
    (``shard_sims``: :func:`sim_peer.replica.election.shard_view` of :func:`sim_peer.replica.hearing_rule.gone_since`), but ``me``."""
    return frozenset(shard_sims) - {me}


def plan(gap: float, lease: float, rivals: frozenset[str]) -> FreezePlan:
    """The plan after a freeze of ``gap`` seconds, with ``lease`` the transport lease and ``rivals`` the sims that
    could have taken over meanwhile."""
    if not rivals:
        return FreezePlan(publish_now=True)
    longer = gap > lease
    return FreezePlan(publish_now=False, listen_s=lease + LISTEN_MARGIN_S if longer else 0.0, reassert=longer)


def ask_for(gap: float) -> float:
    """How long, at most, to ask who holds the shard after a freeze, with ``gap`` the freeze watch's gap."""
    return max(ASK_MIN_S, 10 * gap)
