"""Which compute peer a user's query goes to: the chosen one, the nearest, or every live one in turn.

A world joined with ``compute="spread"`` sends each kinematics query to the next live compute peer
(:class:`~user_peer.spread.RoundRobin`); maps and plans are not spread (a map lives on one peer).
"""

from __future__ import annotations

import logging
from typing import Any, Callable

from fabric.interfaces import ServiceError
from fabric.session import Fabric
from user_peer.spread import SPREAD, RoundRobin

__all__ = ["ComputeRoute"]

log = logging.getLogger("robofabric.user")


class ComputeRoute:
    """``compute``: a compute peer's id, None for the nearest that serves the world, or ``"spread"``."""

    def __init__(self, fabric: Fabric, compute: str | None) -> None:
        self.fabric = fabric
        self.compute = compute
        self._spread = RoundRobin(self.peers) if compute == SPREAD else None
        # (peer, why) of each spread peer that did not answer, whose query the nearest answered instead: said in
        # the log, and what a count of each peer's answers must allow for
        self.skipped: list[tuple[str, str]] = []

    def peers(self) -> list[str]:
        """Ids of the compute peers serving this world (from liveliness): candidates for ``compute``."""
        return sorted(pid for _, pid in self.fabric.live_peers("compute"))

    def ask(self, call: Callable[[str | None], Any]) -> Any:
        """``call(peer)`` with the compute peer for the next kinematics query: the chosen one, the next in
        turn (``compute="spread"``), or None (the nearest). A spread peer that left since the list was read
        is skipped and the nearest asked instead, so a peer going away costs one timeout, not an error."""
        if self._spread is None:
            return call(self.compute)
        peer = self._spread.next()
        try:
            return call(peer)
        except ServiceError as exc:
            if peer is None or not exc.reason.startswith("no reply"):
                raise
            self._spread.forget(peer)
            self.skipped.append((peer, exc.reason))
            log.warning("compute peer %s did not answer (%s): the nearest is asked instead", peer, exc.reason)
            return call(None)

    def navigation_peer(self) -> str | None:
        """The compute peer for maps and plans: the chosen one, else the nearest (a map is not spread)."""
        return None if self.compute == SPREAD else self.compute
