"""Fencing by authority epoch (issue 16): which state a consumer may believe.

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

__all__ = ["AUTHORITY_STREAMS", "Fence", "FenceVerdict", "is_authority_key"]

AUTHORITY_STREAMS = frozenset({"joints", "pose", "scan", "sonar"})
"""Robot streams only a sim authority writes (paths and IK results come from compute and users)."""


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
