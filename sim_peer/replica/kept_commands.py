"""The commands a standby keeps of the last seconds, to apply them again when it takes over.

A command reaches the standby and the primary by different routes, and the standby's last snapshot of the
world was asked for a poll period before the primary died: a joint target sent in that period is in no
snapshot, and without it the arm stops short. So a standby keeps what users sent (robot commands and object
poses) for :data:`KEEP_COMMANDS_S`, never more than a cap in count and bytes whatever clients send, and applies
again, at its take-over, what came after its snapshot was asked for (:class:`sim_peer.replica.following.Follower`).

No zenoh and no lock here: the caller serialises (the replica host's lock); the clock is passed in.
"""

from __future__ import annotations

import time
from collections import deque
from typing import Any, Callable, Iterator, NamedTuple

__all__ = ["CommandBuffer", "Kept", "KEEP_COMMANDS_S", "MAX_KEPT_BYTES", "MAX_KEPT_COMMANDS"]

KEEP_COMMANDS_S = 5.0
"""How long a standby keeps the commands it hears (far more than a poll period: a slow answer)."""

MAX_KEPT_COMMANDS = 4096
MAX_KEPT_BYTES = 16 * 1024 * 1024
"""Caps on what a standby keeps of those seconds (oldest dropped first): a client flooding commands
must not grow a standby's memory; a class's real commands in 5 s are far fewer."""


class Kept(NamedTuple):
    """One message kept: its local arrival (the buffer's clock), its key, the decoded message, its payload bytes."""

    arrival: float
    key: str
    message: Any
    size: int


class CommandBuffer:
    """The last ``keep_s`` seconds of commands, at most ``max_count`` of them and ``max_bytes`` in all."""

    def __init__(
        self,
        *,
        keep_s: float = KEEP_COMMANDS_S,
        max_count: int = MAX_KEPT_COMMANDS,
        max_bytes: int = MAX_KEPT_BYTES,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.keep_s, self.max_count, self.max_bytes = keep_s, max_count, max_bytes
        self.clock = clock
        self._kept: deque[Kept] = deque()
        self._bytes = 0

    @property
    def kept_bytes(self) -> int:
        """The payload bytes of what is kept now (what the byte cap bounds)."""
        return self._bytes

    def __len__(self) -> int:
        return len(self._kept)

    def __iter__(self) -> Iterator[Kept]:
        return iter(list(self._kept))

    def keep(self, key: str, message: Any, size: int = 0) -> None:
        """Keep one message heard now; drop the oldest beyond the window and the caps."""
        now = self.clock()
        self._kept.append(Kept(now, key, message, size))
        self._bytes += size
        while self._kept and (
            self._kept[0].arrival < now - self.keep_s
            or len(self._kept) > self.max_count
            or self._bytes > self.max_bytes
        ):
            self._bytes -= self._kept.popleft().size

    def take_since(self, since: float) -> list[tuple[str, Any]]:
        """(key, message) of what arrived at ``since`` or later, in arrival order; the buffer is emptied."""
        out = [(k.key, k.message) for k in self._kept if k.arrival >= since]
        self.clear()
        return out

    def clear(self) -> None:
        self._kept.clear()
        self._bytes = 0
