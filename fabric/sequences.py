"""Per-key sequence numbers of what one session publishes, bounded, and carried on by a successor.

A standby taking a world over carries on the primary's numbers (:meth:`Sequences.carry_on`), so that a
subscriber never sees a key's sequence go back; nothing a client makes up grows the table past ``max_keys``
(keys beyond are stamped 0).
"""

from __future__ import annotations

import threading

__all__ = ["Sequences"]


class Sequences:
    """Thread-safe: every publishing thread takes its next number here."""

    def __init__(self, max_keys: int) -> None:
        self._lock = threading.Lock()
        self._next: dict[str, int] = {}
        self.max_keys = max_keys

    def take(self, key: str) -> int:
        """The next sequence number on ``key`` (counted from 0)."""
        with self._lock:
            seq = self._next.get(key, 0)
            if seq or len(self._next) < self.max_keys:
                self._next[key] = seq + 1
        return seq

    def under(self, prefix: str = "") -> dict[str, int]:
        """The next sequence number of every key under ``prefix`` this session published on."""
        with self._lock:
            return {k: v for k, v in self._next.items() if k.startswith(prefix)}

    def carry_on(self, seqs: dict[str, int]) -> None:
        """Carry on another session's sequence numbers (a standby taking a world over): never back."""
        with self._lock:
            for k, v in seqs.items():
                if k in self._next or len(self._next) < self.max_keys:
                    self._next[k] = max(self._next.get(k, 0), int(v))
