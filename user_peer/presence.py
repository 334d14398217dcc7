"""Is the world there: the sim peers serving it, from their liveliness tokens, and what a user is told when
one goes or comes back.

One that dies is seen at once, one cut off or frozen within the transport lease. The world is gone when its
last sim left; a sim of a world that stays alive takes its robots with it (``robots_gone``), and a standby of
that sim may serve them again within :data:`FAILOVER_WAIT_S` (``failovers``).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

from fabric.session import Fabric
from user_peer import services
from user_peer.description import WorldDescription
from user_peer.errors import Timeout

log = logging.getLogger("robofabric.user")

__all__ = ["FAILOVER_WAIT_S", "SimPresence"]

FAILOVER_WAIT_S = 15.0
"""How long after a sim left :meth:`SimPresence.on_failover` waits for another sim (its standby) to serve its
robots: a standby takes over within its leader's token loss plus a transport lease (docs/sim.md)."""


def _tell(callbacks: list[Callable[..., None]], what: str, *args: Any) -> None:
    for cb in callbacks:
        try:
            cb(*args)
        except Exception:
            log.exception("%s callback failed", what)


class SimPresence:
    """The live sims of one world. ``closed()``: whether the user's world was closed (a failover watch ends)."""

    def __init__(
        self, fabric: Fabric, world: str, description: WorldDescription, *, closed: Callable[[], bool]
    ) -> None:
        self.fabric = fabric
        self.world = world
        self.description = description
        self.robots_gone: list[str] = []  # robots whose sim left while others serve the world
        self.failovers: list[tuple[str, str, list[str]]] = []  # (sim, the sim that took its robots, robots)
        self._closed = closed
        self._sims: set[str] = set()
        self.arrivals = 0  # sims' tokens come (a sim back from a cut may have missed a command: user_peer.pause)
        self._seen = False
        self._cond = threading.Condition()
        self._lock = threading.Lock()  # the lists above and the callbacks
        self._world_callbacks: list[Callable[[bool, str], None]] = []
        self._gone_callbacks: list[Callable[[str, list[str]], None]] = []
        self._failover_callbacks: list[Callable[[str, str, list[str]], None]] = []

    def watch(self) -> None:
        """Follow the sims' liveliness from now on; and the compute peers', whose going alone matters here: a
        query that finds nobody at once just after a server's token went is asked again for a moment, while it
        reconnects (:data:`fabric.rpc.SERVER_BACK_S`)."""
        self.fabric.watch_peers(self.seen, kind="sim")
        self.fabric.watch_peers(lambda kind, peer, alive: None, kind="compute")

    @property
    def alive(self) -> bool:
        """True while at least one sim peer of this world is alive (its liveliness token is there)."""
        with self._cond:
            return bool(self._sims)

    def ids(self) -> list[str]:
        """Ids of the live sim peers of this world."""
        with self._cond:
            return sorted(self._sims)

    def serves(self, peer_id: str) -> bool:
        """Whether ``peer_id`` is a live sim of this world (read without waiting: called from event callbacks)."""
        return peer_id in self._sims

    def on_world(self, callback: Callable[[bool, str], None]) -> None:
        """``callback(alive, why)`` each time the world goes (its last sim peer left) or comes back."""
        with self._cond:
            self._world_callbacks.append(callback)

    def on_robots_gone(self, callback: Callable[[str, list[str]], None]) -> None:
        """``callback(sim, robots)`` when a sim of a world that stays alive leaves, with the robots it served."""
        with self._lock:
            self._gone_callbacks.append(callback)

    def on_failover(self, callback: Callable[[str, str, list[str]], None]) -> None:
        """``callback(sim, standby, robots)`` when the robots of a sim that left are served again by another."""
        with self._lock:
            self._failover_callbacks.append(callback)

    def wait(self, *, alive: bool = True, timeout: float | None = None) -> bool:
        """Block until the world is there (``alive``: serving, so its description too) or gone; False if that
        did not happen within ``timeout`` (default: the description's ``join_timeout``)."""
        deadline = time.monotonic() + (self.description.join_timeout if timeout is None else timeout)
        with self._cond:
            while bool(self._sims) != alive:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.1))
        if not alive:
            return True
        try:
            self.description.current = self.description.fetch(max(0.0, deadline - time.monotonic()))
        except Timeout:
            return False
        return True

    def seen(self, kind: str, peer_id: str, alive: bool) -> None:
        """A sim's token came (``alive``) or went: the liveliness watch's callback."""
        with self._cond:
            was = bool(self._sims)
            changed = alive != (peer_id in self._sims)
            (self._sims.add if alive else self._sims.discard)(peer_id)
            self.arrivals += alive and changed
            now = bool(self._sims)
            first, self._seen = now and not self._seen, self._seen or now
            callbacks = list(self._world_callbacks) if now != was else []
            self._cond.notify_all()
        if changed and now == was:
            self._sims_changed(peer_id, alive)
        if now == was:
            return
        # "is back" only after the world was there and went: at a start, the first sim is simply there
        why = (
            f"sim peer {peer_id} serves world {self.world!r}"
            if first
            else f"sim peer {peer_id} is back"
            if now
            else f"world {self.world!r} gone: its sim peer {peer_id} left (died, or cut off)"
        )
        if now:
            self.description.forget()  # a restarted sim may describe a different world: ask again
            log.info("world %s: %s", self.world, why)
        else:
            log.warning("%s", why)
        _tell(callbacks, "world", now, why)

    def _sims_changed(self, peer_id: str, alive: bool) -> None:
        """Another sim of a world that stays alive came or went: the description is asked again (a shard's
        robots join or leave it), and the robots a departed sim served are named (``robots_gone``)."""
        info = self.description.current or self.description.known
        self.description.forget()
        if alive or info is None:
            return
        gone = sorted(r.id for r in info.robots if r.sim == peer_id)
        if not gone:
            return  # a standby, or a sim that served nothing we saw
        with self._lock:
            self.robots_gone.extend(gone)
            callbacks = list(self._gone_callbacks)
        log.warning(
            "robots %s gone from world %s: their sim peer %s left (died, or cut off); the other sims' robots go on",
            ", ".join(gone),
            self.world,
            peer_id,
        )
        _tell(callbacks, "robots-gone", peer_id, gone)
        # a standby of that sim (a live sim serving nothing yet) takes them over within its lease: say so when it does
        threading.Thread(target=self._watch_failover, args=(peer_id, gone), name="world-failover", daemon=True).start()

    def _watch_failover(self, sim: str, robots: list[str]) -> None:
        """Ask the world's description until another sim serves every robot ``sim`` served, for up to
        :data:`FAILOVER_WAIT_S`; then tell it as ``sim X failed over to Y`` (log, ``failovers``, :meth:`on_failover`).
        Without this, a standby's take-over reached scripts only as "robots ... gone from world"."""
        deadline = time.monotonic() + FAILOVER_WAIT_S
        while not self._closed() and time.monotonic() < deadline:
            with self._cond:
                if sim in self._sims:
                    return  # the same sim came back (a pause): not a failover
            try:
                info = services.world_info(self.fabric, timeout=1.0)
            except Exception:  # no sim answers now (the standby is taking over), or the session closed
                info = None
            if info is not None:
                served = {r.id: r.sim for r in info.robots}
                takers = sorted({served[r] for r in robots if served.get(r) not in (None, "", sim)})
                if takers and all(served.get(r) not in (None, "", sim) for r in robots):
                    self._failed_over(sim, ", ".join(takers), robots)
                    return
            time.sleep(0.25)

    def _failed_over(self, sim: str, to: str, robots: list[str]) -> None:
        with self._lock:
            self.failovers.append((sim, to, list(robots)))
            callbacks = list(self._failover_callbacks)
        log.warning("sim %s failed over to %s: robots %s go on in world %s", sim, to, ", ".join(robots), self.world)
        _tell(callbacks, "failover", sim, to, list(robots))
