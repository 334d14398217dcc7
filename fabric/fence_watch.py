"""Which authority state a session believes: its :class:`~fabric.fencing.SimFence`, fed by the sims' tokens.

:mod:`fabric.fencing` decides (pure, no I/O); this module is the session's side of it: it asks the fence
about every stamped message the session receives (a publication or a reply), and once terms are in use
it follows the world's sim tokens, so that when the last sim goes the fence resets and a world restarted
from scratch (term 1) is believed again after an earlier take-over.
"""

from __future__ import annotations

import threading
from typing import Any

import zenoh

from fabric import keys
from fabric.fencing import SimFence, fenced_scopes
from fabric.token_watch import TokenWatch

__all__ = ["FenceWatch"]


class FenceWatch:
    """``believe(key, message)`` for one session; what it declares goes into ``resources``, which the session
    undeclares when it closes. Counts ``stale_authority`` and ``fence_resets`` in ``counters``."""

    def __init__(
        self,
        session: zenoh.Session,
        world: str,
        fence: SimFence,
        *,
        counters: Any,
        resources: list[Any],
    ) -> None:
        self._session = session
        self._world = world
        self.fence = fence
        self._counters = counters
        self._resources = resources
        self._lock = threading.Lock()
        self._watching = False

    def believe(self, key: str, msg: Any) -> bool:
        """False for authority state stamped with a lower term than one already heard."""
        header = getattr(msg, "header", None)
        if header is None:
            return True
        scopes = fenced_scopes(key, msg)
        if scopes is None:
            return True
        if header.term and not self._watching:
            self._watch_sims()
        if self.fence.believe(header.term, header.source, scopes):
            return True
        self._counters["stale_authority"] += 1  # a lower term, or in flight when its sim left
        return False

    def _watch_sims(self) -> None:
        with self._lock:
            if self._watching:
                return
            self._watching = True

        def on_token(key: str, alive: bool) -> None:
            try:
                pid = keys.parse(key).leaf
            except ValueError:
                return
            if alive:
                self.fence.sim_seen(pid)
            elif self.fence.sim_left(pid):
                self._counters["fence_resets"] += 1

        try:  # every going is checked with the router: one it did not mean would refuse a live sim's every sample
            watch = TokenWatch(self._session, keys.peers_all(self._world, "sim"), on_token)
        except Exception:  # a closing session
            return
        self._resources.append(watch)
