"""A primary that may have been frozen: muzzled until it knows whether another sim holds its world now.

The fabric's freeze watch (:mod:`fabric.authority_stamp`) calls back when the gap between two publications is longer
than ``gap`` (half the transport lease by default: a freeze long enough for the others to drop our token is
always caught, with margin; a false alarm, a starved process, costs one query, muzzled). What it does then is the
pure core :mod:`sim_peer.replica.freeze_rule`'s plan; this shell gathers the sims that could have taken over, listens, asks
``srv/state`` and publishes again.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable, Protocol

from fabric import keys
from fabric.interfaces import NoReply, ServiceError, WorldState
from fabric.rpc import STALE
from fabric.session import Fabric
from sim_peer.replica import election as el
from sim_peer.replica import freeze_rule as fr

__all__ = ["FreezeGuard", "Electing", "ShardOf"]


class Electing(Protocol):
    """What the guard asks of the election's shell (:class:`sim_peer.replica.roles.Roles`)."""

    @property
    def role(self) -> str:
        """This sim's role now."""
        ...

    def gone_since(self, began: float) -> set[str]:
        """The sims alive now or gone since ``began``."""
        ...

    def heard(self, source: str, term: int) -> None:
        """Authority state stamped with ``term`` came from ``source``."""
        ...

    def step(self, ev: el.Event) -> None:
        """Apply one observation to the election."""
        ...


class ShardOf(Protocol):
    """What the guard reads of this sim's shard (:class:`sim_peer.shards.directory.ShardDirectory`)."""

    def view(self, live: frozenset[str]) -> frozenset[str]:
        """The live sims of this shard."""
        ...

    def about_mine(self, state: Any) -> bool:
        """Whether a ``srv/state`` answer is this shard's."""
        ...


EMPTY_LOOKS = 3
"""How many looks at the sims' tokens a frozen primary takes before it believes no rival is there."""
LOOK_TIMEOUTS_S = (1.0, 2.0, 4.0)
"""Each look's wait for the tokens and for the answers: longer each time, as a process starved for a few seconds
(CI's run at load 7-10 saw three one-second looks come back empty with the rival serving all along)."""
LOOK_AGAIN_S = 0.5
"""Between two looks: a going its fence heard is checked with the router within this (fabric.token_watch: 0.5 s)."""


class FreezeGuard:
    """What a primary does after a gap in its own publications longer than ``gap`` seconds.

    Its collaborators: ``fabric``; ``roles`` (:class:`Electing`); ``shard`` (:class:`ShardOf`); ``stopping``;
    ``announce``; ``clock``. It keeps no state that changes."""

    def __init__(
        self,
        fabric: Fabric,
        *,
        roles: Electing,
        shard: ShardOf,
        stopping: threading.Event,
        announce: Callable[[str], None],
        gap: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fabric = fabric
        self._roles, self._shard, self._stopping, self.announce = roles, shard, stopping, announce
        self.clock = clock
        self.gap = gap if gap is not None else fr.watch_gap(fabric.config.lease_ms / 1000.0)

    def watch(self) -> None:
        """Ask the fabric to call :meth:`on_freeze` after a gap (a primary's, from when it serves)."""
        self.fabric.stamp.watch_freeze(self.gap, self.on_freeze)

    def on_freeze(self, gap: float) -> None:
        """Frozen for ``gap`` s: muzzled until it is known whether another sim may hold the world now.

        With no other sim alive when the freeze began (nothing could have taken over), publish again at
        once. Otherwise, after a gap longer than the lease (the others dropped our token, and our session
        may not even know yet that its link died), listen muzzled for a lease: a new authority's streams
        reach us once the session is back, and hearing its higher term steps us down before anything goes
        out; then ask ``srv/state``, step down if a higher term answers, carry on otherwise (:func:`freeze_rule.plan`)."""
        f = self.fabric
        lease = f.config.lease_ms / 1000.0
        seen = frozenset(self._roles.gone_since(fr.began(self.clock(), gap)))
        todo = fr.plan(gap, lease, fr.rivals(self._shard.view(seen), f.peer_id))
        if todo.publish_now:
            f.stamp.unmuzzle()
            self.announce(
                f"sim {f.peer_id}: paused {gap:.1f} s with no other sim in the world; publishing again (term {f.stamp.term})"
            )
            return
        if todo.listen_s:
            self._stopping.wait(todo.listen_s)
        self._ask_who_leads()
        if self._roles.role == el.PRIMARY:
            if todo.reassert:
                self._roles.step(el.Resumed())
            f.stamp.unmuzzle()
            self.announce(f"sim {f.peer_id}: frozen {gap:.1f} s, still the authority (term {f.stamp.term})")

    def _ask_who_leads(self) -> None:
        """Once connected again, ask ``srv/state`` who holds this shard now; a higher term heard steps us down."""
        f = self.fabric
        deadline = self.clock() + fr.ask_for(self.gap)
        empty = 0
        while self.clock() < deadline and not self._stopping.is_set() and self._roles.role == el.PRIMARY:
            if not f.connected():
                time.sleep(0.1)  # not connected yet: nobody to ask, nobody to tell
                continue
            wait = LOOK_TIMEOUTS_S[min(empty, len(LOOK_TIMEOUTS_S) - 1)]
            replies = []
            missed = ""
            try:
                replies = f.rpc.query(keys.srv(f.world, "state"), timeout=wait, expected=WorldState, all_replies=True)
            except NoReply:
                # the sims' tokens only say what the miss was: the ask goes out whatever they show (a whole run at
                # load 14 saw three looks find no rival's token, 1, 2 and 4 s each, the rival serving all along)
                others = [pid for _, pid in f.live_peers("sim", timeout=wait) if pid != f.peer_id]
                missed = "no_reply" if others else "no_token"
            except ServiceError as exc:
                # standbys answer with a refusal: no other authority. An answer this session's fence refused
                # is no answer: a sim whose token it heard go a moment ago (a stall of this process drops
                # every link of it) is refused until its token is checked back (fabric.token_watch)
                missed = "refused" if exc.reason.startswith(STALE) else ""
                replies = []
            if missed and empty < EMPTY_LOOKS - 1:
                # rivals were there when the freeze began: at load a look at the tokens, or the ask, can come back
                # empty (the suite's run saw a rival that served all along missed), so look again a few times,
                # each waiting longer; counted by what was missed
                f.counters[f"freeze_look_{missed}"] += 1
                empty += 1
                time.sleep(LOOK_AGAIN_S)
                continue
            for rep in replies:
                if self._shard.about_mine(rep.message):
                    self._roles.heard(rep.message.header.source, rep.message.header.term)
            return
