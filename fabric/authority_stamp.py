"""What a session stamps on and withholds from the world when its peer is an authority (a sim).

The writing side of replicated authority, kept in one place (the reading side, which state to believe, is
:mod:`fabric.fencing`; who holds the world, :mod:`sim_peer.replica.election`; the host that runs a sim as primary
or standby, :mod:`sim_peer.replica.replica_host`):

- the **term** stamped on every header (0 for every peer that is no authority);
- the **muzzle**: while set, nothing is published and no query is answered (an authority unsure it still
  is one, or stepping down);
- the **freeze watch**: a gap longer than ``freeze_gap`` between two publications means the process was
  frozen (SIGSTOP, a stalled VM, a starved CPU): the stamp muzzles itself and calls ``on_freeze(gap)``
  in a new thread, whose owner decides when to :meth:`AuthorityStamp.unmuzzle`. Time spent muzzled is
  never read as a freeze.

:class:`fabric.session.Fabric` holds one as ``fabric.stamp``; its peer reads ``stamp.term`` and ``stamp.muzzled``
and calls ``stamp.muzzle()``, ``stamp.unmuzzle()`` and ``stamp.watch_freeze()`` there, and sets the term with
:meth:`fabric.session.Fabric.assume_term` (which also fences what the session believes below it).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable

log = logging.getLogger("robofabric")

__all__ = ["AuthorityStamp"]


class AuthorityStamp:
    """Thread-safe: publications, queries and a host's threads all read it. ``clock``: monotonic seconds."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._lock = threading.Lock()
        self._clock = clock
        self.term = 0
        self.muzzled = False
        self.freezes = 0
        self._freeze_gap: float | None = None
        self._on_freeze: Callable[[float], None] | None = None
        self._last_put = 0.0

    def assume_term(self, term: int) -> None:
        with self._lock:
            self.term = term

    def muzzle(self) -> None:
        with self._lock:
            self.muzzled = True

    def unmuzzle(self) -> None:
        """Publish again; the freeze watch starts over (read as a freeze, the time spent muzzled after a long
        pause muzzled a sim again at every unmuzzle, for ever)."""
        with self._lock:
            self.muzzled = False
            self._last_put = 0.0

    def watch_freeze(self, gap: float | None, on_freeze: Callable[[float], None] | None) -> None:
        """Muzzle on a gap longer than ``gap`` s between publications and call ``on_freeze(gap)``; None: off."""
        with self._lock:
            self._freeze_gap, self._on_freeze = gap, on_freeze
            self._last_put = 0.0

    def may_put(self) -> bool:
        """Called right before each publication: False while muzzled, or when this one ends a freeze."""
        with self._lock:
            if self.muzzled:
                return False
            if self._freeze_gap is None:
                return True
            now = self._clock()
            gap = now - self._last_put if self._last_put else 0.0
            self._last_put = now
            if gap <= self._freeze_gap:
                return True
            self.muzzled = True
            self.freezes += 1
            on_freeze = self._on_freeze
        log.warning("%.1f s without publishing (frozen?): muzzled until the authority is confirmed", gap)
        if on_freeze is not None:
            threading.Thread(target=on_freeze, args=(gap,), name="fabric-freeze", daemon=True).start()
        return False
