"""A primary that hears no one stops its robots, and goes on when it hears again.

A primary cut off from the fabric (its cable pulled, its router gone, its own token dropped: what
:meth:`sim_peer.roles.Roles.deaf` reads) keeps simulating, but nobody hears it: a standby takes the world over from
the last state it heard, and whatever the cut-off primary's robots did meanwhile is lost. The soak saw an arm's
joints jump 0.356 rad across such a take-over: the primary, cut off for a second, had stepped 2 s of sim time on
with the arm moving. Nor may it move a robot for an owner it can no longer hear. So while it is deaf it stops every
robot as a release stops it (a base brakes within its limits, an arm holds where it is) and refuses commands
(:meth:`sim_peer.commanding.CommandPipeline.hold`); when it hears again it takes commands again, and its robots stay
where they stopped until their owners send more. It says both in its log.

A look every :data:`POLL_S` on a thread of its own, started when the host first serves.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING

from sim_peer import election as el

if TYPE_CHECKING:
    from sim_peer.replica_host import ReplicaHost

log = logging.getLogger("robofabric.sim")

__all__ = ["DeafStop", "POLL_S", "REASON"]

POLL_S = 0.05
"""How often a serving host looks whether it hears anyone."""
REASON = "this sim hears no one"


class DeafStop:
    """Holds the robots of ``host``'s peer while the host is a primary that hears no one."""

    def __init__(self, host: "ReplicaHost") -> None:
        self.host = host
        self.holds = 0  # how many times it held the robots
        self._thread: threading.Thread | None = None

    def watch(self) -> None:
        """Start looking (once; the host serving again after a rebuild goes on with the same look)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="sim-deaf-stop", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        while not self.host.stopping.wait(POLL_S):
            try:
                self.look()
            except Exception:  # a closing session or peer: the next look, or the host's end
                log.debug("deaf stop look failed", exc_info=True)

    def look(self) -> None:
        """Hold the serving peer's robots if this primary is deaf now, let them go if it hears again."""
        h = self.host
        peer = h.peer
        if peer is None or h.role != el.PRIMARY:
            return
        deaf = h.roles.deaf()
        held = bool(peer.commands.held)
        if deaf and not held:
            peer.commands.hold(REASON)
            self.holds += 1
            h.announce(f"sim {h.fabric.peer_id}: hears no one (link down, its own token gone or just frozen); its robots "
                       "stop (bases brake, arms hold) and commands are refused until it hears again")
        elif held and not deaf:
            peer.commands.resume()
            h.announce(f"sim {h.fabric.peer_id}: hears again; commands are accepted (its robots stay where they stopped)")
