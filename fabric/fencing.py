"""Fencing by authority epoch: which state a consumer may believe.

A world's authority (the sim peer that owns the robots and the ownership records) stamps its
authority epoch, the *term*, on every message it writes (:attr:`fabric.interfaces.Header.term`).
A standby that takes the world over raises the term; a primary that comes back from a freeze still
stamps the old one until it notices and steps down. Consumers keep the highest term they have seen
per world and ignore authority state stamped with a lower one, so for them there is never more than
one authority, whatever the wire carries for a moment.

Only authority keys are fenced (:func:`is_authority_key`): robot state streams the sim writes, the
ownership records and the world description. Everything users, compute peers and tools write carries
term 0 and is never compared. Pure: no zenoh, no clock.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

from fabric import keys

__all__ = ["AUTHORITY_STREAMS", "Fence", "FenceVerdict", "SimFence", "MAX_DEPARTED_SIMS", "is_authority_event", "is_authority_key"]

AUTHORITY_STREAMS = frozenset({"joints", "pose", "scan", "sonar"})
"""Robot streams only a sim authority writes (paths and IK results come from compute and users)."""

MAX_DEPARTED_SIMS = 256
"""Ids of sims whose token went, kept so their late samples cannot re-raise a reset fence (bounded:
anyone may declare a token)."""


def is_authority_key(key: str) -> bool:
    """Whether ``key`` carries state only the world's sim authority writes."""
    try:
        p = keys.parse(key)
    except ValueError:
        return False
    if p.category == "robot":
        return p.leaf in AUTHORITY_STREAMS
    if p.category == "own":  # own/{obj}: the record (own/{obj}/by/{user} is a user's request)
        return True
    if p.category == "srv":
        return p.subject in ("world", "state")
    return False


NOT_SIM_EVENTS = frozenset({keys.DECODE, "compute"})
"""Event chunks others than sims write: decode reports (every login, ``event/decode/by/{login}``) and the
compute peers' (``event/compute/**``). A class's router lets only sims write the rest of ``event/**``."""


def is_authority_event(key: str) -> bool:
    """Whether an event on ``key`` can only have come from a sim (docs/security.md): a client acts on such an
    event alone (and only when its source is the object's authority); what any login may write is display-only."""
    try:
        p = keys.parse(key)
    except ValueError:
        return False
    return p.category == "event" and p.subject not in NOT_SIM_EVENTS


@dataclass(frozen=True, slots=True)
class FenceVerdict:
    """``accept``: believe the message; ``raised``: it carried a higher term than any before."""

    accept: bool
    raised: bool = False


class Fence:
    """The highest authority epoch seen; thread-safe. ``check(term)`` says whether to believe a message."""

    def __init__(self, term: int = 0) -> None:
        self._term = int(term)
        self._lock = threading.Lock()
        self.stale = 0

    @property
    def term(self) -> int:
        return self._term

    def check(self, term: int) -> FenceVerdict:
        """Accept ``term`` if it is at least the highest seen (raising that mark); count and refuse it otherwise."""
        with self._lock:
            if term < self._term:
                self.stale += 1
                return FenceVerdict(False)
            raised = term > self._term
            self._term = term
            return FenceVerdict(True, raised)

    def reset(self) -> None:
        """Forget the highest term: the world's last sim left, and a sim started afresh begins at term 1."""
        with self._lock:
            self._term = 0

    def raise_to(self, term: int) -> None:
        """Never go below ``term`` from now on (an authority taking over fences its own past)."""
        with self._lock:
            self._term = max(self._term, int(term))


class SimFence:
    """One world's :class:`Fence` and the sim peers it follows (their liveliness tokens); thread-safe.

    When the world's last sim leaves, the fence resets, so a world restarted from scratch (term 1) is
    believed again after an earlier take-over; a departed sim's late samples, in flight when it left,
    are refused so that they cannot raise the fence again over the new sim. Sessions and the recorder's
    sink keep one per world they fence."""

    def __init__(self, fence: Fence | None = None) -> None:
        self.fence = fence if fence is not None else Fence()
        self.sims: set[str] = set()
        self.resets = 0
        self._departed: set[str] = set()
        self._lock = threading.Lock()

    def believe(self, term: int, source: str) -> bool:
        """Whether authority state stamped ``term`` by ``source`` may be believed."""
        with self._lock:
            departed = bool(term) and source in self._departed
        return not departed and self.fence.check(term).accept

    def sim_seen(self, peer_id: str) -> None:
        """A sim peer of the world is alive (its token appeared)."""
        with self._lock:
            self.sims.add(peer_id)
            self._departed.discard(peer_id)

    def sim_left(self, peer_id: str) -> bool:
        """A sim peer is gone; True when it was the last one and the fence was reset."""
        with self._lock:
            self.sims.discard(peer_id)
            if len(self._departed) < MAX_DEPARTED_SIMS:
                self._departed.add(peer_id)
            if self.sims:
                return False
            self.resets += 1
        self.fence.reset()
        return True
