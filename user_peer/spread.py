"""Spreading stateless kinematics queries over every compute peer of a world.

A classroom may run several compute peers; IK, FK and Jacobian queries carry
everything they need, so any peer can answer any of them. ``RoundRobin`` takes
the live peers from a callable (liveliness, in the API) and hands them out in
turn, re-reading the list at most every ``refresh_s`` so a peer that joins gets
work and one that leaves stops getting it. Mapping and planning are not spread:
a map lives in the peer that folded the scans in.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

__all__ = ["SPREAD", "RoundRobin"]

SPREAD = "spread"  # the ``compute=`` value that asks for round robin instead of one peer


class RoundRobin:
    """The next live compute peer, in turn; ``None`` when none is known (then the nearest answers)."""

    def __init__(
        self, peers: Callable[[], list[str]], *, refresh_s: float = 2.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self._peers = peers
        self._refresh_s = refresh_s
        self._clock = clock
        self._lock = threading.Lock()
        self._known: list[str] = []
        self._read_at: float | None = None
        self._last: str | None = None

    def next(self) -> str | None:
        with self._lock:
            now = self._clock()
            if self._read_at is None or now - self._read_at >= self._refresh_s or not self._known:
                self._known = sorted(set(self._peers()))
                self._read_at = now
            if not self._known:
                return None
            # the one after the last handed out, so a changed list neither repeats nor skips a peer
            later = [p for p in self._known if self._last is None or p > self._last]
            self._last = later[0] if later else self._known[0]
            return self._last

    def forget(self, peer: str) -> None:
        """Drop a peer that did not answer until the list is read again."""
        with self._lock:
            if peer in self._known:
                self._known.remove(peer)
