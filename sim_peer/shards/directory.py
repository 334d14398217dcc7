"""Which live sim serves which robots of a world: the shard directory a sim's election reads.

Several sims may serve one world, each the authority of its own robots (docs/sim.md, "Several sims, one
world"). A sim asks every live sim on ``srv/state`` with a shard query (:data:`SHARD_QUERY`) which robots it
serves or would serve at a take-over (standbys answer too), keeps the answers of the live ones, and counts
only its own shard's sims in its election (:func:`sim_peer.replica.election.shard_view`). A sim not asked yet counts as
one of ours: one world, one shard, what every sim did before shards.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable, Iterable

from fabric import keys
from fabric.interfaces import Event, Header, WorldState
from fabric.session import Fabric
from sim_peer.replica import election as el

__all__ = ["ShardDirectory", "SHARD_QUERY"]

SHARD_QUERY = "shard"
"""The ``Event.kind`` of a ``srv/state`` query asking a sim which robots it serves (its answer's ``data["robots"]``)."""


class ShardDirectory:
    """This sim's shard (``mine``: the robots it serves, or would serve at a take-over) and the other live sims'.

    It talks to the rest of the sim through what its constructor names, never the host: the ``fabric`` it asks on,
    ``live`` (the live sims now, from the election's shell), ``stopping`` (set when the host closes) and ``on_learnt``
    (called with this shard's live sims once a shard learnt in the background may change the election's view).
    Its own lock guards the shards learnt and the learning flags; it calls none of those collaborators while holding
    it, so a caller holding its own lock may call in. ``mine`` is replaced whole (a frozenset), never changed."""

    def __init__(
        self,
        fabric: Fabric,
        mine: Iterable[str],
        *,
        live: Callable[[], frozenset[str]],
        stopping: threading.Event,
        on_learnt: Callable[[frozenset[str]], None],
    ) -> None:
        self.fabric = fabric
        self.mine = frozenset(mine)
        self._live = live
        self._stopping = stopping
        self._on_learnt = on_learnt
        self._lock = threading.Lock()
        self.shards: dict[str, frozenset[str]] = {}  # live sim -> the robots it serves (from srv/state, asked)
        self._learning = self._learn_again = False  # a shard query under way, and another wanted after it

    def about_mine(self, state: Any) -> bool:
        """Whether a ``srv/state`` answer is this shard's (another shard's terms are none of our election's)."""
        return isinstance(state, WorldState) and any(r.id in self.mine for r in state.robots)

    def same_shard(self, peer_id: str) -> bool:
        """Whether a live sim belongs to this shard; one not asked yet counts as ours (one world, one shard:
        what every sim did before shards)."""
        with self._lock:
            robots = self.shards.get(peer_id)
        return robots is None or bool(robots & self.mine)

    def view(self, live: frozenset[str]) -> frozenset[str]:
        """The live sims of this shard: the election of a shard counts no other shard's sims."""
        with self._lock:
            shards = dict(self.shards)
        return el.shard_view(live, shards, self.fabric.peer_id, self.mine)

    def standbys(self, live: Iterable[str]) -> list[str]:
        """The other live sims that follow a robot of this shard, by id."""
        me, live = self.fabric.peer_id, set(live)
        with self._lock:
            shards = dict(self.shards)
        return sorted(p for p, robots in shards.items() if p != me and p in live and robots & self.mine)

    def answer(self, role: str) -> Event:
        """This sim's answer to a shard query, primary or standby: its robots."""
        return Event(
            kind=SHARD_QUERY,
            reason=role,
            object="",
            data={"robots": sorted(self.mine)},
            header=Header(wall_ns=time.time_ns(), source=self.fabric.peer_id),
        )

    def learn(self) -> None:
        """Ask every live sim which robots it serves (``srv/state`` with a shard query; standbys answer too)."""
        f = self.fabric
        try:
            replies = f.rpc.query(
                keys.srv(f.world, "state"),
                Event(kind=SHARD_QUERY, reason="ask"),
                timeout=1.0,
                expected=Event,
                all_replies=True,
            )
        except Exception:
            return  # nobody else (or closing): unknown sims count as ours
        live = self._live()  # before taking our lock: the election's shell guards its live sims with its own
        with self._lock:
            for rep in replies:
                robots = rep.message.data.get("robots") if isinstance(rep.message.data, dict) else None
                if rep.message.kind == SHARD_QUERY and isinstance(robots, (list, tuple)) and rep.source:
                    self.shards[rep.source] = frozenset(str(r) for r in robots)
            for gone in [p for p in self.shards if p not in live]:
                del self.shards[gone]

    def learn_soon(self) -> None:
        """Learn a new sim's shard on a thread of its own (a token's callback must not wait for a query), then
        let the election count the live sims of this shard again (``on_learnt``)."""
        with self._lock:
            if self._learning or self._stopping.is_set():
                self._learn_again = True
                return
            self._learning, self._learn_again = True, False

        def run() -> None:
            while True:
                self.learn()
                with self._lock:
                    again = self._learn_again and not self._stopping.is_set()
                    self._learn_again = False
                    if not again:
                        self._learning = False
                if not again:
                    break
            self._on_learnt(self.view(self._live()))

        threading.Thread(target=run, name="sim-shards", daemon=True).start()
