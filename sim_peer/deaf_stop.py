"""A primary cut off from its world stops its robots, and goes on when it hears again; one that was only late goes on.

A primary cut off from the fabric (its cable pulled, its router gone, its own token dropped: what
:meth:`sim_peer.roles.Roles.cut` reads) keeps simulating, but nobody hears it: a standby takes the world over from
the last state it heard, and whatever the cut-off primary's robots did meanwhile is lost. The soak saw an arm's
joints jump 0.356 rad across such a take-over: the primary, cut off for a second, had stepped 2 s of sim time on
with the arm moving. Nor may it move a robot for an owner it can no longer hear. So while it is cut off it stops
every robot as a release stops it (a base brakes within its limits, an arm holds where it is) and refuses commands
(:meth:`sim_peer.commanding.CommandPipeline.hold`, code ``held``); when it hears again it takes commands again, and
its robots stay where they stopped until their owners send more.

A primary that was merely late (paused by SIGSTOP, a laptop's hiccup, or starved of CPU on a loaded machine: its
heartbeat came late, :meth:`sim_peer.roles.Roles.frozen`) simulated nothing meanwhile, so it has nothing to lose; it
proves its link as a take-over does (its router answers a query, :func:`sim_peer.roles.router_answers`) and serves
commands on at once. It holds only if the router does not answer. A proof counts for the freeze it follows (a new
freeze, or a cut, needs a new one); while the heartbeat is late right now, for :data:`PROOF_S`.

The log says which case it was: "hears no one" with the cause (the link down, its token gone, or a freeze its
router did not answer after), "was late" when a freeze ended with the router answering.

A look every :data:`POLL_S` on a thread of its own, started when the host first serves.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING

from sim_peer import election as el
from sim_peer.roles import router_answers

if TYPE_CHECKING:
    from sim_peer.replica_host import ReplicaHost

log = logging.getLogger("robofabric.sim")

__all__ = ["DeafStop", "POLL_S", "PROOF_S", "ASK_S", "REASON"]

POLL_S = 0.05
"""How often a serving host looks whether it hears anyone."""
PROOF_S = 0.5
"""How long a router's answer proves the link while the heartbeat is late right now (a starved process)."""
ASK_S = 1.0
"""How long the router is given to answer (a round trip: a millisecond on a LAN, more on a starved machine)."""
REASON = "this sim hears no one"


class DeafStop:
    """Holds the robots of ``host``'s peer while the host is a primary cut off from its world."""

    def __init__(self, host: "ReplicaHost") -> None:
        self.host = host
        self.holds = 0  # how many times it held the robots
        self.lates = 0  # how many freezes ended with the router answering (nothing held)
        self.proven_at = float("-inf")  # when the router last answered (monotonic)
        self._told_thaw = float("-inf")  # the freeze (Roles.thawed_at) the log last told of
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

    def why(self) -> str:
        """Why this primary hears no one now ('' : it hears): cut off, or late and its router does not answer."""
        roles = self.host.roles
        cut = roles.cut()
        if cut:
            return cut
        if not roles.frozen() or self._proven():
            return ""
        if self.host.fabric.config.profile == "embedded" or router_answers(self.host.fabric, ASK_S):
            self.proven_at = time.monotonic()  # the router holds it: nobody took the world meanwhile
            return ""
        return f"frozen or starved {roles.late_s:.1f} s, and its router does not answer"

    def _proven(self) -> bool:
        """Whether the router answered since the last freeze and the last cut (within :data:`PROOF_S` while the
        heartbeat is late right now)."""
        roles = self.host.roles
        now = time.monotonic()
        since = max(roles.thawed_at, roles.unlinked_at, roles.own_gone_at)
        if now - roles.last_tick > self.host.fabric.config.lease_ms / 2000.0:
            since = max(since, now - PROOF_S)
        return self.proven_at > since

    def look(self) -> None:
        """Hold the serving peer's robots if this primary is cut off now, let them go once it hears again; say so
        when it was only late."""
        h = self.host
        peer = h.peer
        if peer is None or h.role != el.PRIMARY:
            return
        why = self.why()
        held = bool(peer.commands.held)
        if why and not held:
            peer.commands.hold(REASON)
            self.holds += 1
            h.announce(f"sim {h.fabric.peer_id}: hears no one ({why}); its robots stop (bases brake, arms hold) and "
                       "commands are refused until it hears again")
        elif held and not why:
            peer.commands.resume()
            self._told_thaw = h.roles.thawed_at
            h.announce(f"sim {h.fabric.peer_id}: hears again (its router answers); commands are accepted (its robots "
                       "stay where they stopped)")
        elif not why and h.roles.thawed_at > self._told_thaw and self.proven_at > h.roles.thawed_at:
            self._told_thaw = h.roles.thawed_at
            self.lates += 1
            h.announce(f"sim {h.fabric.peer_id}: was late ({h.roles.late_s:.1f} s frozen or starved), not cut off: its "
                       "router answers; commands are served on")
