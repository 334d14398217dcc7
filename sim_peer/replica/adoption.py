"""The scene objects after their sim: a shard adopts them when their authority went and nobody took them over.

In a world served by several shards, the scene objects have one authority, the world's first sim. When a sim
leaves and no standby of its shard has taken the objects over within ``after_s``, the serving primary with the
lowest id adopts them: it serves its robots and the objects again, one term up, with the objects where it
mirrored them (every sim moves them on the users' poses). When to look and who adopts are the pure core
:mod:`sim_peer.replica.adoption_rule`'s decisions; this shell waits, asks ``srv/world`` and serves again.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import replace
from typing import TYPE_CHECKING

from fabric import keys
from fabric.interfaces import ServiceError, WorldInfo
from sim_peer.replica import adoption_rule as ar
from sim_peer.replica import election as el

if TYPE_CHECKING:
    from sim_peer.replica.replica_host import ReplicaHost

log = logging.getLogger("robofabric.sim")

__all__ = ["ObjectAdoption"]


class ObjectAdoption:
    """Whether, and when, a serving sim that is not the objects' authority becomes it."""

    def __init__(self, host: "ReplicaHost", after_s: float | None = None) -> None:
        self.host = host
        # after a sim leaves, how long a shard waits for the objects' standby (a take-over takes well under a
        # lease) before asking whether the scene objects still have an authority
        self.after_s = after_s if after_s is not None else ar.wait_s(host.fabric.config.lease_ms / 1000.0)
        self._watch = ar.Watch()  # a wait under way, a departure since its last look (adoption_rule)

    def soon(self) -> None:
        """A sim left: after ``after_s``, see whether the scene objects went with it (one thread at a time)."""
        h = self.host
        with h.lock:
            self._watch, start = ar.departed(self._watch, serves_objects=h.objects or h.closed)
        if not start:
            return

        def run() -> None:
            while not h.stopping.wait(self.after_s):
                with h.lock:
                    self._watch, look = ar.waited(self._watch, serves_objects=h.objects or h.closed)
                if not look:
                    return
                try:
                    self.adopt_if_orphaned()
                except Exception:  # a closing session; the next departure asks again
                    log.debug("adopting the scene objects failed", exc_info=True)
            with h.lock:
                self._watch = ar.stopped(self._watch)

        threading.Thread(target=run, name="sim-adopt-objects", daemon=True).start()

    def adopt_if_orphaned(self) -> bool:
        """Serve the scene objects when no live sim describes them and this is the lowest-id sim that serves a
        part of the world (every shard asks the same union, so one adopts); True when this one did."""
        h = self.host
        f, me = h.fabric, h.fabric.peer_id
        try:
            replies = f.rpc.query(keys.srv(f.world, "world"), timeout=2.0, expected=WorldInfo, all_replies=True)
        except ServiceError:
            return False
        parts = {r.source: bool(r.message.objects) for r in replies if r.source}
        if not ar.adopter(parts, me, has_objects=bool(h.world.objects)):
            return False
        with h.lock:
            if h.role != el.PRIMARY or h.peer is None or h.objects or h.closed:
                return False
            t0 = time.monotonic()
            h.objects = True  # before the capture: the state carries the objects where this sim mirrored them
            state, _ = h.stop_serving()
            term = h.election.term + 1
            h.roles.set_term(term)
            h.serve(replace(state, header=replace(state.header, term=term)))
            h.role_token.show(h.election, True)  # serving again, under the new term
        h.announce(
            f"sim {me}: no sim serves the scene objects any more; serving {', '.join(h.world.objects)} "
            f"with my robots (term {term}) in {(time.monotonic() - t0) * 1000:.0f} ms"
        )
        return True
