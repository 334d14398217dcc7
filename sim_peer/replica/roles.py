"""A sim's role in its shard's election, as it lives it: the live sims it sees, and what each change makes it do.

The pure core (:mod:`sim_peer.replica.election`) decides; this part feeds it what the session observes (the sims'
liveliness tokens, the terms heard on streams and ``srv/state``) and carries out its effects through what its
constructor names, never the host: a take-over on a thread of its own (``take_over``), a step-down (muzzled at
once, then the host's ``run`` returns), a term asserted again after a freeze (``reassert``), a new leader
announced, the role shown (``show_role``), the scene objects looked after (``adopt_soon``).

The first complete view of the live sims comes before any change counts (:meth:`Roles.join`): the election
reads a leader missing from a view as gone, so the view must not be a history still arriving.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from typing import Callable, Protocol

from sim_peer.replica import election as el
from sim_peer.replica import hearing_rule as hr
from sim_peer.replica.hearing_rule import AUDIBLE_S, RECHECK_LEASES, TICK_S

from fabric.session import Fabric

__all__ = ["Roles", "ShardView", "MAX_GONE", "AUDIBLE_S", "SETTLE_S", "TICK_S", "router_answers"]

MAX_GONE = 256
"""How many departed sims' times are remembered (made-up sim tokens must not grow the record)."""
SETTLE_S = 0.3
"""How long a sim's lost token waits at most, its link up all the while, before the election hears of it
(:meth:`Roles.settle`). When this sim's own link dies (the router killed), the tokens that came through it go
while the session still lists its router: in the lab a standby read its leader's loss on a link that seemed up
and took the world over from no state (CI saw it too). A router that answers (:func:`router_answers`) ends the wait
at once; one that cannot be asked makes a killed leader's fail-over wait this much longer."""
SETTLE_POLL_S = 0.02


def router_answers(fabric: Fabric, timeout: float) -> bool:
    """Whether this session's router answers a query on its admin space now: a round trip (a millisecond on a
    LAN) that a dead link cannot make. A router whose admin space is closed to this login, or not ours, answers
    nothing: then only the time tells (:data:`SETTLE_S`)."""
    try:
        zid = next(iter(fabric.session.info.routers_zid()), None)
        if zid is None:
            return False
        return any(r.ok is not None for r in fabric.session.get(f"@/{zid}/router", timeout=timeout))
    except Exception:  # a closing session
        return False


class ShardView(Protocol):
    """What the roles ask of this sim's shard (:class:`sim_peer.shards.directory.ShardDirectory`)."""

    def learn(self) -> None:
        """Ask every live sim which robots it serves, now."""
        ...

    def learn_soon(self) -> None:
        """Learn the shards on a thread of its own, then let the election look again."""
        ...

    def view(self, live: frozenset[str]) -> frozenset[str]:
        """The live sims of this shard."""
        ...


class Roles:
    """The election state of one host, the live sims it sees and when others went.

    Its own lock guards what it sees (the live sims, when they went, its flags). The election itself changes under
    the lock of what the host serves (``serving_lock``, passed in): a rebuild reads the term and serves under a new
    one (:meth:`set_term`) with no step-down between. It calls no collaborator while holding either lock."""

    def __init__(
        self,
        fabric: Fabric,
        election: el.Election,
        *,
        shard: ShardView,
        serving_lock: threading.RLock,
        stopping: threading.Event,
        announce: Callable[[str], None],
        take_over: Callable[[float, str | None], None],
        reassert: Callable[[int], None],
        show_role: Callable[[el.Election], None],
        adopt_soon: Callable[[], None],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fabric = fabric
        self._shard, self._serving_lock, self._stopping = shard, serving_lock, stopping
        self._announce, self._take_over, self._reassert = announce, take_over, reassert
        self._show_role, self._adopt_soon = show_role, adopt_soon
        self._lock = threading.RLock()
        self.clock = clock  # monotonic seconds: every time this shell reads, and passes to the cores
        self.election = election
        self.live: set[str] = set()
        self.gone_at: dict[str, float] = {}  # sim id -> when its token went (monotonic): was it there when we froze?
        self.settled = False  # the first complete view of the live sims is in (join)
        self.stepped_down = threading.Event()
        self.own_gone_at = float("-inf")  # when the router last dropped our own token (monotonic)
        self.rechecking = False  # a look at the live sims is due once this sim's own link is back (deaf_recheck)
        self.taking_over: threading.Thread | None = None
        # when each sim was last heard (monotonic); a standby made by a step-down heard its leader just now
        self.heard_at: dict[str, float] = {election.leader: self.clock()} if election.leader else {}
        self.relooking = False  # a look at the live sims is due once a missing but audible leader goes quiet
        # until when the tokens seen may still be arriving: a host made by a step-down (it starts with a leader),
        # for its first leases from join
        self.fresh_until = float("inf") if election.leader else float("-inf")
        self.beat = hr.Heartbeat()  # this process's own heartbeat (frozen: see frozen()), replaced by each tick
        self.settling = False  # a token's loss waits to be judged (settle)

    @property
    def role(self) -> str:
        return self.election.role

    def join(self) -> None:
        """Watch the sims' tokens, take a first complete view of the live ones, and let the election decide on it.
        The watch comes first (what it hears meanwhile is kept, but decides nothing until the view is settled),
        then a liveliness query."""
        f = self.fabric
        f.watch_peers(self.on_sim, kind="sim")
        try:
            initial = {pid for _, pid in f.live_peers("sim", timeout=2.0)}
        except Exception:
            initial = set()
        with self._lock:
            self.live |= initial | {f.peer_id}
        if len(self.live) > 1:
            self._shard.learn()
        self.await_leader(self.election.leader)
        self.beat = hr.Heartbeat(last_tick=self.clock())
        threading.Thread(target=self._tick, name="sim-heartbeat", daemon=True).start()
        with self._lock:
            self.settled = True
            if self.fresh_until > 0:
                self.fresh_until = self.clock() + RECHECK_LEASES * f.config.lease_ms / 1000.0
            live = frozenset(self.live)
        self.step(el.Peers(self._shard.view(live)))

    def await_leader(self, leader: str) -> None:
        """A standby that already follows ``leader`` (a primary that just stepped down on hearing its higher
        term) waits up to a transport lease for its token: the first liveliness query of a fresh session
        can answer before the router's tokens have reached it (seen in the lab after a healed partition:
        the view held only our own token, and the stepped-down primary took the world back at once, with
        its own stale state). A leader whose token does not show within the lease is gone: take over."""
        if self.role != el.STANDBY or not leader or leader == self.fabric.peer_id:
            return
        deadline = self.clock() + self.fabric.config.lease_ms / 1000.0
        while self.clock() < deadline and not self._stopping.is_set():
            with self._lock:
                if leader in self.live:
                    return
            time.sleep(0.02)

    def on_sim(self, kind: str, peer_id: str, alive: bool) -> None:
        """A sim's token came or went."""
        with self._lock:
            (self.live.add if alive else self.live.discard)(peer_id)
            if not alive:
                self.gone_at[peer_id] = self.clock()
                if len(self.gone_at) > MAX_GONE:
                    self.gone_at.pop(min(self.gone_at, key=self.gone_at.__getitem__))
            settled = self.settled
        if alive:
            self._shard.learn_soon()  # which shard it is (a standby of ours, or another shard's sim)
        if alive or not settled:
            return  # a token appearing (or the history repeating one) never starts a take-over; nor does
            # one going before the first view is settled (join() steps on the whole view then)
        if peer_id == self.fabric.peer_id:
            with self._lock:
                self.own_gone_at = self.clock()
        if peer_id == self.fabric.peer_id or self.deaf():
            self.deaf_recheck("its own token gone" if peer_id == self.fabric.peer_id else self.deaf_words())
            return
        self.settle(self.clock())

    def settle(self, lost_at: float) -> None:
        """Judge a sim's lost token once this sim's router answered after it (:func:`router_answers`), or its link
        stayed up :data:`SETTLE_S`: if the link went down meanwhile (or our own token went), every token went with
        the link, and the look waits for the link (:meth:`deaf_recheck`); else the election looks at the sims alive
        then (the lost one may have been the scene objects' authority)."""
        with self._lock:
            if self.settling:
                return  # the look under way takes this loss in too
            self.settling = True

        def judge() -> None:
            unlinked = False
            try:
                answered = router_answers(self.fabric, SETTLE_S)  # at once on a live link (a router's round trip)
                while (
                    not unlinked
                    and not answered
                    and self.clock() - lost_at < SETTLE_S
                    and not self._stopping.wait(SETTLE_POLL_S)
                ):
                    unlinked = not self.fabric.connected()
                unlinked = (
                    unlinked or not self.fabric.connected() or hr.unlinked_since(self.beat, self.own_gone_at, lost_at)
                )
            finally:
                with self._lock:
                    self.settling = False
            if self._stopping.is_set():
                return
            if unlinked or self.deaf():
                self.deaf_recheck(
                    f"its link went {1000 * (self.clock() - lost_at):.0f} ms after a sim's token"
                    if unlinked
                    else self.deaf_words()
                )
                return
            with self._lock:
                live = frozenset(self.live)
            self.step(el.Peers(self._shard.view(live)))
            if self.role == el.PRIMARY:
                self._adopt_soon()

        threading.Thread(target=judge, name="sim-settle", daemon=True).start()

    def _tick(self) -> None:
        """This process's heartbeat: a gap between two ticks longer than half a lease is a freeze (SIGSTOP, a starved
        process), after which the tokens seen are not to be trusted for a lease (:meth:`frozen`); a tick that finds
        the link down marks when (:meth:`settle`)."""
        gap = self.fabric.config.lease_ms / 2000.0
        while not self._stopping.wait(TICK_S):
            self.beat = hr.tick(self.beat, self.clock(), gap=gap, connected=self.fabric.connected())

    def frozen(self) -> bool:
        """Whether this process was frozen just now: its heartbeat is late, or came back from a gap within the last
        lease. A standby paused past the lease wakes with a link the router dropped and a stale state; the tokens it
        sees go (every one of them, its session's link being dead) before its session reconnects, and it must not
        read that as its leader's death (the soak saw a paused standby take the world back with older epochs).
        The distrust lasts a lease and as long again as the freeze was (up to five leases): a session that slept
        through the router dropping it reads its link's news late (a standby paused 4 s read its leader's token gone
        more than a lease after it woke, link up, and took the world over from no state) (:func:`hearing_rule.frozen`)."""
        return hr.frozen(self.beat, self.clock(), self.fabric.config.lease_ms / 1000.0)

    def deaf(self) -> bool:
        """Whether this sim hears no one now: its link is down, the router no longer holds its own token, or this
        process was just frozen."""
        return bool(self.cut()) or self.frozen()

    def deaf_words(self) -> str:
        """Why :meth:`deaf` holds, in the log's words: the cut, or the freeze."""
        return self.cut() or hr.freeze_words(self.beat, self.clock(), self.fabric.config.lease_ms / 1000.0) or "deaf"

    def cut(self) -> str:
        """Why this sim's link is gone now ('' : it is not): the link is down, or the router no longer holds its
        own token. A freeze alone is not a cut (:meth:`frozen`; :mod:`sim_peer.replica.deaf_stop` asks the router then)."""
        with self._lock:
            seen, gone_at = self.fabric.peer_id in self.live, self.own_gone_at
        return hr.cut(connected=self.fabric.connected(), own_token_seen=seen, own_gone_at=gone_at, now=self.clock())

    def deaf_recheck(self, why: str) -> None:
        """Our own link went (this sim cut off, the router restarted, this process paused past the lease): every sim's
        token went with it, and none of them need have gone. A standby that took the world over then would serve it
        from a state that stops at the cut, and its higher term would step down the primary that served everyone
        meanwhile (the soak saw epochs go back). So: once the link and our own token are back, and
        :data:`RECHECK_LEASES` leases (and half a second) have passed for the live sims' tokens to come back too, the
        election looks at the sims then alive: a leader whose token did not come back is gone. A cut in the window
        (a second restart of the router) starts it again once the link is back."""
        with self._lock:
            if self.rechecking:
                return
            self.rechecking = True
        if self.role == el.STANDBY:
            self._announce(
                f"standby {self.fabric.peer_id}: deaf ({why}); the live sims are looked "
                f"at again {RECHECK_LEASES} leases after it hears again"
            )

        def recheck() -> None:
            try:
                window = hr.recheck_window(self.fabric.config.lease_ms / 1000.0)
                back = hr.NOT_YET
                while not self._stopping.is_set() and self.clock() < back:
                    # cut off (again): the window starts once it hears
                    now = self.clock()
                    back = hr.recheck(
                        back, now, deaf=self.deaf() or hr.recently_unlinked(self.beat, now), window=window
                    )
                    time.sleep(0.05)
            finally:
                with self._lock:
                    self.rechecking = False
            if self._stopping.is_set():
                return
            with self._lock:
                live = frozenset(self.live)
            if self.deaf():
                self.deaf_recheck(self.deaf_words())  # cut off (or frozen) again meanwhile
                return
            self.step(el.Peers(self._shard.view(live)))
            if self.role == el.PRIMARY:
                self._adopt_soon()
            elif self.election.leader in live:
                self._announce(
                    f"standby {self.fabric.peer_id}: hearing again; following {self.election.leader} (term {self.election.term})"
                )

        threading.Thread(target=recheck, name="sim-deaf-recheck", daemon=True).start()

    def live_sims(self) -> frozenset[str]:
        """The sims whose tokens are live now (this one's too)."""
        with self._lock:
            return frozenset(self.live)

    def shards_learnt(self, view: frozenset[str]) -> None:
        """The shard directory learnt which sims share this shard (``view``: its live ones): once the first view
        is settled, the election counts them again."""
        if self.settled:
            self.step(el.Peers(view))

    def gone_since(self, began: float) -> set[str]:
        """The sims alive now or gone since ``began`` (monotonic)."""
        with self._lock:
            return set(hr.gone_since(self.live, self.gone_at, began))

    def heard(self, source: str, term: int) -> None:
        """Authority state stamped with ``term`` came from ``source``."""
        if term > 0:
            if source != self.fabric.peer_id:
                if source not in self.heard_at and len(self.heard_at) >= MAX_GONE:
                    self.heard_at.pop(min(self.heard_at, key=self.heard_at.__getitem__))
                self.heard_at[source] = self.clock()
            self.step(el.Heard(source, term))

    def audible(self) -> frozenset[str]:
        """The sims heard within :data:`AUDIBLE_S`, while the tokens seen may still be arriving: the first
        :data:`RECHECK_LEASES` leases of this host (a primary that just stepped down, its session back from a
        pause past the lease, can see its leader's token seconds late), or a leader already found missing but
        heard (:meth:`relook`). Later a token's loss is trusted at once (a killed leader's goes with its link, and
        waiting would only delay its fail-over); a deaf sim's view is not trusted at all (:meth:`deaf_recheck`).

        At any time, a leader still heard whose token this sim has not seen since it follows it is alive: a fresh
        session's first view can lack tokens that have not reached it yet (a restarted standby that heard its leader's
        term at once, before its token, took the world over from no state while the leader served on). Call with the
        serving lock held: the leader read here is the one the election then judges (:meth:`step`)."""
        e = self.election
        unseen = (e.leader,) if e.leader and not e.leader_seen else ()
        return hr.audible(
            dict(self.heard_at), self.clock(), fresh_until=self.fresh_until, relooking=self.relooking, unseen=unseen
        )

    def relook(self) -> None:
        """The leader is missing from the live sims but still heard: look again once it has been quiet for
        :data:`AUDIBLE_S` (it may be gone then: a killed sim's last samples), or sooner if it speaks no more, or once
        its token has come."""
        with self._lock:
            if self.relooking:
                return
            self.relooking = True
        self._announce(
            f"standby {self.fabric.peer_id}: the token of {self.election.leader} is missing, but it is still heard; "
            "waiting until it falls silent before taking over"
        )

        def again() -> None:
            try:
                while not self._stopping.is_set():
                    leader = self.election.leader
                    quiet = self.clock() - self.heard_at.get(leader, float("-inf"))
                    if quiet >= AUDIBLE_S or leader in self.live_sims():
                        break  # fallen silent, or its token came: the live sims tell now
                    self._stopping.wait(AUDIBLE_S - quiet + 0.01)
            finally:
                with self._lock:
                    self.relooking = False
            if self._stopping.is_set():
                return
            with self._lock:
                live = frozenset(self.live)
            self.step(el.Peers(self._shard.view(live)))

        threading.Thread(target=again, name="sim-relook", daemon=True).start()

    def set_term(self, term: int) -> None:
        """Serve on under ``term`` (a move or an adoption took a new one; call with the serving lock held)."""
        with self._serving_lock:
            self.election = replace(self.election, term=term)
        self._show_role(self.election)

    def step(self, ev: el.Event) -> None:
        """Apply one observation to the election and carry out its effects. A view of the live sims taken while this
        sim is deaf, or waits after being deaf, decides nothing (whoever took it: a token's loss, a shard learnt
        after a token came back); the wait ends with a view of its own (:meth:`deaf_recheck`)."""
        if isinstance(ev, el.Peers) and self.settled:
            with self._lock:
                waiting = self.rechecking
            if waiting or self.deaf():
                self.deaf_recheck(self.deaf_words())
                return
        with self._serving_lock:
            if isinstance(ev, el.Peers):
                # what is heard now, under the lock the election changes under: a leader followed since the view was
                # taken (its term heard on another thread meanwhile) is judged with what is heard of it
                ev = replace(ev, audible=self.audible())
            followed = self.election.leader
            self.election, effects = el.step(self.election, ev)
            leader = self.election.leader
            deferred = (
                isinstance(ev, el.Peers)
                and self.election.role == el.STANDBY
                and leader not in ev.live
                and leader in ev.audible
            )
        if deferred:
            self.relook()
        for e in effects:
            if e.kind == "take_over":
                # why, for whoever reads the log after a surprise (a take-over in a router's restart, say)
                self._announce(
                    f"standby {self.fabric.peer_id}: the token of {followed or 'the primary'} is gone (live sims: "
                    f"{', '.join(sorted(ev.live)) if isinstance(ev, el.Peers) else '?'}; link "
                    f"{'up' if self.fabric.connected() else 'down'}); taking over with term {e.term}"
                )
                t = threading.Thread(
                    target=self._take_over, args=(self.clock(), followed), name="take-over", daemon=True
                )
                self.taking_over = t
                t.start()
            elif e.kind == "step_down":
                self.fabric.stamp.muzzle()  # from now on nothing with the old term goes out
                self._announce(f"sim {self.fabric.peer_id}: {e.leader} holds term {e.term}; stepping down to standby")
                self.stepped_down.set()
            elif e.kind == "reassert":
                self._reassert(e.term)
            elif e.kind == "follow" and self.role == el.STANDBY:
                self._announce(f"standby {self.fabric.peer_id}: following {e.leader} (term {e.term})")
        self._show_role(self.election)  # a take-over shows once it serves (ReplicaHost.take_over)
