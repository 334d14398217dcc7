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
from typing import Callable, Protocol

from fabric import keys
from fabric.interfaces import ServiceError, WorldInfo
from fabric.session import Fabric
from sim_peer.replica import adoption_rule as ar

log = logging.getLogger("robofabric.sim")

__all__ = ["ObjectAdoption", "ObjectsServer"]


class ObjectsServer(Protocol):
    """What adoption asks of the sim that serves the world (the replica's host)."""

    def serves_objects(self) -> bool:
        """Whether there is nothing to adopt here: this sim is the objects' authority already, or closed."""
        ...

    def scene_objects(self) -> tuple[str, ...]:
        """The scene objects of this sim's world (a world with none has nothing to adopt)."""
        ...

    def adopt_objects(self) -> int | None:
        """Serve the scene objects too, one term up, in one step under the server's own lock (what it serves and
        its term change together); the new term, or None when this sim is not a serving primary any more, or
        serves them already, or closed."""
        ...


class ObjectAdoption:
    """Whether, and when, a serving sim that is not the objects' authority becomes it.

    It talks to the rest of the sim through what its constructor names: the ``fabric`` it asks ``srv/world`` on,
    the ``server`` that serves again (:class:`ObjectsServer`), ``stopping`` (set when the host closes), ``announce``
    and ``clock`` (monotonic seconds). Its own lock guards the wait's state (:class:`adoption_rule.Watch`); it calls
    no collaborator while holding it."""

    def __init__(
        self,
        fabric: Fabric,
        server: ObjectsServer,
        *,
        stopping: threading.Event,
        announce: Callable[[str], None],
        clock: Callable[[], float] = time.monotonic,
        after_s: float | None = None,
    ) -> None:
        self.fabric = fabric
        self.server = server
        self.stopping = stopping
        self.announce = announce
        self.clock = clock
        # after a sim leaves, how long a shard waits for the objects' standby (a take-over takes well under a
        # lease) before asking whether the scene objects still have an authority
        self.after_s = after_s if after_s is not None else ar.wait_s(fabric.config.lease_ms / 1000.0)
        self._lock = threading.Lock()
        self._watch = ar.Watch()  # a wait under way, a departure since its last look (adoption_rule)

    def soon(self) -> None:
        """A sim left: after ``after_s``, see whether the scene objects went with it (one thread at a time)."""
        serves = self.server.serves_objects()
        with self._lock:
            self._watch, start = ar.departed(self._watch, serves_objects=serves)
        if not start:
            return

        def run() -> None:
            while not self.stopping.wait(self.after_s):
                serves = self.server.serves_objects()
                with self._lock:
                    self._watch, look = ar.waited(self._watch, serves_objects=serves)
                if not look:
                    return
                try:
                    self.adopt_if_orphaned()
                except Exception:  # a closing session; the next departure asks again
                    log.debug("adopting the scene objects failed", exc_info=True)
            with self._lock:
                self._watch = ar.stopped(self._watch)

        threading.Thread(target=run, name="sim-adopt-objects", daemon=True).start()

    def adopt_if_orphaned(self) -> bool:
        """Serve the scene objects when no live sim describes them and this is the lowest-id sim that serves a
        part of the world (every shard asks the same union, so one adopts); True when this one did."""
        f, me = self.fabric, self.fabric.peer_id
        try:
            replies = f.rpc.query(keys.srv(f.world, "world"), timeout=2.0, expected=WorldInfo, all_replies=True)
        except ServiceError as exc:  # not an answer: asked again after the next wait
            with self._lock:
                self._watch = ar.unanswered(self._watch)
            log.info("%s: whether the scene objects still have a sim went unanswered (%s); asking again", me, exc)
            return False
        parts = {r.source: bool(r.message.objects) for r in replies if r.source}
        objects = self.server.scene_objects()
        if not ar.adopter(parts, me, has_objects=bool(objects)):
            return False
        t0 = self.clock()
        term = self.server.adopt_objects()
        if term is None:
            return False
        self.announce(
            f"sim {me}: no sim serves the scene objects any more; serving {', '.join(objects)} "
            f"with my robots (term {term}) in {(self.clock() - t0) * 1000:.0f} ms"
        )
        return True
