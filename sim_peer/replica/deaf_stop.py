"""A primary cut off from its world stops its robots, and goes on when it hears again; one that was only late goes on.

A primary cut off from the fabric (its cable pulled, its router gone, its own token dropped: what
:meth:`sim_peer.replica.roles.Roles.cut` reads) keeps simulating, but nobody hears it: a standby takes the world over from
the last state it heard, and whatever the cut-off primary's robots did meanwhile is lost. The soak saw an arm's
joints jump 0.356 rad across such a take-over: the primary, cut off for a second, had stepped 2 s of sim time on
with the arm moving. Nor may it move a robot for an owner it can no longer hear. So while it is cut off it stops
every robot as a release stops it (a base brakes within its limits, an arm holds where it is) and refuses commands
(:meth:`sim_peer.serving.commanding.CommandPipeline.hold`, code ``held``); when it hears again it takes commands again, and
its robots stay where they stopped until their owners send more.

A primary that was merely late (paused by SIGSTOP, a laptop's hiccup, or starved of CPU on a loaded machine: its
heartbeat came late, :meth:`sim_peer.replica.roles.Roles.frozen`) simulated nothing meanwhile, so it has nothing to lose; it
proves its link as a take-over does (its router answers a query, :func:`sim_peer.replica.roles.router_answers`) and serves
commands on at once. It holds only if the router does not answer. A proof counts for the freeze it follows (a new
freeze, or a cut, needs a new one); while the heartbeat is late right now, for :data:`PROOF_S`.

The log says which case it was: "hears no one" with the cause (the link down, its token gone, or a freeze its
router did not answer after), "was late" when a freeze ended with the router answering.

A look every :data:`POLL_S` on a thread of its own, started when the host first serves. The decisions are the pure
core :mod:`sim_peer.replica.deaf_rule`'s; this shell gathers each look, asks the router when the core says so, and carries
out the effects (hold, resume, say it was late).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import replace
from typing import TYPE_CHECKING, Callable, Protocol

from fabric.session import Fabric
from sim_peer.replica import deaf_rule as dr
from sim_peer.replica import hearing_rule as hr
from sim_peer.replica.deaf_rule import PROOF_S
from sim_peer.replica.roles import router_answers

if TYPE_CHECKING:
    from sim_peer.serving.peer import SimPeer

log = logging.getLogger("robofabric.sim")

__all__ = ["DeafStop", "Hearing", "POLL_S", "PROOF_S", "ASK_S", "REASON"]

POLL_S = 0.05
"""How often a serving host looks whether it hears anyone."""
ASK_S = 1.0
"""How long the router is given to answer (a round trip: a millisecond on a LAN, more on a starved machine)."""
REASON = "this sim hears no one"


class Hearing(Protocol):
    """What a look reads of whether this sim hears (:class:`sim_peer.replica.roles.Roles`)."""

    beat: hr.Heartbeat
    own_gone_at: float

    def cut(self) -> str:
        """Why this sim's link is gone now ('' : it is not)."""
        ...

    def frozen(self) -> bool:
        """Whether this process was frozen just now."""
        ...


class DeafStop:
    """Holds the robots of the serving peer while this sim is a primary cut off from its world.

    Its collaborators: ``fabric``; ``hearing`` (:class:`Hearing`); ``serving`` (the peer this sim serves as its
    primary now, None otherwise); ``stopping``; ``announce``; ``clock``. Its state is the look thread's alone."""

    def __init__(
        self,
        fabric: Fabric,
        *,
        hearing: Hearing,
        serving: "Callable[[], SimPeer | None]",
        stopping: threading.Event,
        announce: Callable[[str], None],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fabric = fabric
        self._hearing, self._serving, self._stopping, self.announce = hearing, serving, stopping, announce
        self.clock = clock
        self.state = dr.DeafState()  # what the core remembers: holds, lates (counted), the router's last answer
        self._thread: threading.Thread | None = None

    def watch(self) -> None:
        """Start looking (once; the host serving again after a rebuild goes on with the same look)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="sim-deaf-stop", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        while not self._stopping.wait(POLL_S):
            try:
                self.look()
            except Exception:  # a closing session or peer: the next look, or the host's end
                log.debug("deaf stop look failed", exc_info=True)

    def _seen(self, held: bool) -> dr.Look:
        """What the core needs to know now, the router asked if the core says so."""
        f, hearing = self.fabric, self._hearing
        seen = dr.Look(
            now=self.clock(),
            held=held,
            cut=hearing.cut(),
            frozen=hearing.frozen(),
            beat=hearing.beat,
            own_gone_at=hearing.own_gone_at,
            lease=f.config.lease_ms / 1000.0,
        )
        if dr.must_ask(self.state, seen) and (f.config.profile == "embedded" or router_answers(f, ASK_S)):
            seen = replace(seen, answered_at=self.clock())
        return seen

    def look(self) -> None:
        """Hold the serving peer's robots if this primary is cut off now, let them go once it hears again; say so
        when it was only late."""
        peer, me = self._serving(), self.fabric.peer_id
        if peer is None:
            return
        self.state, effects = dr.step(self.state, self._seen(bool(peer.commands.held)))
        for e in effects:
            if isinstance(e, dr.Hold):
                peer.commands.hold(REASON)
                self.announce(
                    f"sim {me}: hears no one ({e.why}); its robots stop (bases brake, arms hold) "
                    "and commands are refused until it hears again"
                )
            elif isinstance(e, dr.Resume):
                peer.commands.resume()
                self.announce(
                    f"sim {me}: hears again (its router answers); commands are accepted (its "
                    "robots stay where they stopped)"
                )
            else:
                self.announce(
                    f"sim {me}: was late ({e.late_s:.1f} s frozen or starved), not cut off: its "
                    "router answers; commands are served on"
                )
