"""A peer's handle on a world: one zenoh session plus the fabric's habits.

:class:`Fabric` opens the session for a profile, declares the peer's
liveliness token ``rf/{world}/peer/{kind}/{id}``, encodes and stamps what it
publishes, and decodes what it receives. A malformed payload never reaches a
callback: it is counted, logged and published as an event under
``rf/{world}/event/decode/{peer}`` a few times per subscription per
:data:`fabric.reports.REPORT_INTERVAL` (with the count of what was suppressed, quoting at
most ~200 characters of what the client sent), and the peer goes on. Nothing a
client makes up (keys, payloads) grows a peer's memory: publishers and sequence
counters are kept for at most :data:`MAX_KEYS` keys.

A session's parts with a job of their own live in modules of their own, and the session holds one of
each: ``fabric.rpc`` (services: serve, query, call; :mod:`fabric.rpc`), ``fabric.stamp`` (the term it
stamps, its muzzle and freeze watch; :mod:`fabric.authority_stamp`), ``fabric.seqs`` (per-key sequence
numbers; :mod:`fabric.sequences`), ``fabric.reports`` (events and reports of bad input, rate-limited;
:mod:`fabric.reports`) and the fence over what it believes (:mod:`fabric.fence_watch`).
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections import Counter
from typing import Any, Callable, Iterable

import zenoh

from fabric import keys
from fabric.authority_stamp import AuthorityStamp
from fabric.codec import DecodeError, decode, encode, load_plugins
from fabric.config import FabricConfig, default_peer_id
from fabric.declared import Declared, Told, encode_told
from fabric.exit import at_exit
from fabric.fence_watch import FenceWatch
from fabric.standstill import Standstill
from fabric.token_watch import TokenWatch
from fabric.fencing import SimFence
from fabric.history import LatestThenLive
from fabric.interfaces import Header
from fabric.matching import is_matched, wait_matched
from fabric.publishers import declare_publisher
from fabric.reports import Reports
from fabric.rpc import Rpc
from fabric.sequences import Sequences

log = logging.getLogger("robofabric")

MAX_KEYS = 1024
"""Publishers and per-key sequence numbers kept per session; keys beyond are published uncached."""

__all__ = ["CLOSE_S", "Fabric", "close_within", "shutdown_event", "undeclare_all"]

CLOSE_S = 10.0
"""How long ``Fabric.close`` waits for zenoh to close its session (milliseconds, as a rule)."""


def undeclare_all(resources: list[Any]) -> None:
    """Undeclare what a service declared on a shared session, newest first; what a closing session
    already took away is skipped, so a service can close before or after its session."""
    for res in reversed(resources):
        try:
            res.undeclare()
        except Exception:  # already gone with a closing session
            pass


def close_within(close: Callable[[], object], limit: float, what: str) -> bool:
    """Run ``close`` on a thread of its own and wait for it ``limit`` s at most; False (and a warning) when it did not
    end by then, and it is left to the process's exit. A zenoh session's close once never returned (a whole suite
    beside a CPU hog, a test's teardown blocked in zenoh's runtime for 20 minutes, so the suite never ended): nothing
    a peer does may block for ever, its own closing least of all."""
    done = threading.Event()

    def run() -> None:
        try:
            close()
        except Exception:  # a session already closing, or gone with its runtime
            pass
        finally:
            done.set()

    try:
        threading.Thread(target=run, name=f"close {what}", daemon=True).start()
    except RuntimeError:  # the interpreter is finalizing (atexit, Python 3.12+): no new thread, close here
        run()
    if done.wait(limit):
        return True
    log.warning("%s did not close within %.1f s: left to the process's exit", what, limit)
    return False


class Fabric:
    """One peer in one world. A context manager; ``close()`` is idempotent."""

    def __init__(self, config: FabricConfig, *, kind: str, peer_id: str | None = None, token: bool = True) -> None:
        load_plugins()  # every installed message type, before the first sample can arrive
        self.config = config
        self.world = config.world
        self.kind = kind
        self.peer_id = keys.validate_id(peer_id or default_peer_id(kind), what="peer id")
        self.counters: Counter[str] = Counter()
        self.stamp = AuthorityStamp()
        """Term, muzzle and freeze watch (:mod:`fabric.authority_stamp`): what this peer stamps and withholds as an
        authority (0 and never muzzled for every peer that is no authority)."""
        self.sim_fence = SimFence()
        """The world's sims as this session follows them (once terms are in use), and its fences: the highest
        term heard per authority object (:func:`fabric.fencing.authority_scopes`); :meth:`subscribe` and
        ``rpc.query`` drop state below it."""
        self.seqs = Sequences(MAX_KEYS)
        """The next sequence number per key this session published on (:mod:`fabric.sequences`)."""
        self._lock = threading.Lock()
        self._closed = False
        self._resources: list[Any] = []
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._probes: dict[str, zenoh.Publisher] = {}  # key -> a publisher to remote subscribers only (listened())
        self._local_exprs: frozenset[str] = frozenset()  # this session's own subscriptions that take its samples
        self._local_keys: dict[str, bool] = {}  # key -> whether one of them takes it (emptied when one is added)
        self.declared = Declared()
        """What this peer's code subscribed to and serves, told on its token's key (:mod:`fabric.declared`)."""
        self.session = zenoh.open(config.zenoh_config())
        self.opened_at = time.monotonic()
        """When the session opened (monotonic s): a query that finds nobody soon after asks again (fabric.rpc)."""
        self._link_lost_at = float("-inf")
        """When this client last lost a link to its router (monotonic s; never for a router or a peer): a query ridden over
        it asks again (fabric.rpc), and a going heard about then is checked (fabric.token_watch)."""
        self._link_back_at = float("-inf")
        """When a link came back after one was lost (monotonic s): its routes come a moment after it (fabric.rpc)."""
        self._token_gone_at = float("-inf")
        """When a token watched here last went (monotonic s): a closing link takes its tokens first (fabric.rpc)."""
        self._standstill: Standstill | None = None
        """When this process last stood still (paused, starved): a query that found nobody then waits to hear whether
        its link closed (fabric.rpc). A client's alone: a router's or a peer's links are not lost so."""
        if config.profile == "client":  # a client's transports are its links to routers; a router's are its clients'
            self._resources.append(self.session.info.declare_transport_events_listener(self._on_transport))
            self._standstill = Standstill()
            self._resources.append(self._standstill)
        self._fence_watch = FenceWatch(
            self.session,
            self.world,
            self.sim_fence,
            counters=self.counters,
            resources=self._resources,
        )
        self.rpc = Rpc(
            self.session,
            counters=self.counters,
            stamp=self.stamp,
            header=self.header,
            believe=self._fence_watch.believe,
            resources=self._resources,
            linked=self._linked if config.profile == "client" else None,
            lost_at=lambda: self._link_lost_at,
            back_at=lambda: self._link_back_at,
            token_gone_at=lambda: self._token_gone_at,
            stood_still=self._standstill.last
            if self._standstill is not None
            else lambda: (float("-inf"), float("-inf")),
            opened_at=self.opened_at,
            declared=self.declared,
        )
        """Services: ``rpc.serve``, ``rpc.query``, ``rpc.call`` (:mod:`fabric.rpc`)."""
        self.reports = Reports(
            self.world,
            counters=self.counters,
            publish=self.publish,
            header=self.header,
            reporter=lambda: config.identity() or self.peer_id,
        )
        """Events and reports of bad input, rate-limited: ``reports.emit``, ``reports.bad_payload``,
        ``reports.should_report`` (:mod:`fabric.reports`)."""
        self.token = (
            self.session.liveliness().declare_token(keys.peer(self.world, kind, self.peer_id)) if token else None
        )
        if token:  # who asks what this peer subscribes to and serves (list, info, ps -v) asks it here
            self._resources.append(
                self.session.declare_queryable(keys.peer(self.world, kind, self.peer_id), self._tell_declared)
            )
        # zenoh's callback threads keep the interpreter alive until the session closes: a script that
        # never calls close() must still exit (fabric/exit.py)
        self._cancel_exit = at_exit(self.close)

    # ------------------------------------------------------------------ lifecycle

    def __enter__(self) -> "Fabric":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Undeclare everything this peer declared and close the session; safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._cancel_exit()
        declared = ([self.token] if self.token is not None else []) + list(self._resources)

        def close() -> None:  # the undeclarations too: each waits in zenoh, as the session's close does
            undeclare_all(declared)
            self.session.close()

        if not close_within(close, CLOSE_S, f"the zenoh session of {self.kind} {self.peer_id}"):
            self.counters["closes_hung"] += 1

    # ------------------------------------------------------------------ publishing

    def header(self, key: str, *, stamp: float = 0.0) -> Header:
        """A header for the next message on ``key``: per-key sequence, wall time now, this peer as source."""
        return Header(
            stamp=float(stamp),
            wall_ns=time.time_ns(),
            seq=self.seqs.take(key),
            source=self.peer_id,
            term=self.stamp.term,
        )

    def publish(self, key: str, msg: Any) -> int:
        """Encode and put ``msg`` on ``key``; returns the payload size in bytes.

        On a latched key (:func:`fabric.keys.is_latched`: scene objects, maps, paths) the publisher
        keeps its last sample for subscribers that join later and ask for history."""
        if self.stamp.muzzled:
            self.counters["muzzled"] += 1
            return 0
        payload = encode(msg)
        pub = self._publisher(key)
        if not self.stamp.may_put():
            self.counters["muzzled"] += 1
            return 0
        if pub is None:  # a safety net: callers should not publish on made-up keys
            self.counters["uncached_puts"] += 1
            self.session.put(key, payload)
            self.counters["published"] += 1
            return len(payload)
        pub.put(payload)  # right after the check: a thread stopped between the two sends one stale sample
        self.counters["published"] += 1
        return len(payload)

    def _publisher(self, key: str) -> Any:
        """The cached publisher of ``key`` (declared on first use); None past :data:`MAX_KEYS`."""
        pub = self._publishers.get(key)
        if pub is None and len(self._publishers) < MAX_KEYS:
            pub = declare_publisher(self.session, key)
            self._publishers[key] = pub
            self._resources.append(pub)
        return pub

    def listened(self, key: str) -> bool:
        """Whether a subscriber of ``key`` is known to this session now: another session's (a router told it), or
        one of its own that takes its own samples. True where zenoh does not say (a latched or kept key's
        advanced publisher, a key past :data:`MAX_KEYS`).

        A put nobody listens to is dropped by zenoh at once; what a stream costs is reading, building and
        encoding its message, which a sim then skips. Asked of a publisher to remote subscribers only: the sim's
        own ``remote_only`` subscriptions of every sim's joints and poses (for terms and mirrors) match each of
        its streams, and would say someone listens to all of them."""
        known = self._local_keys  # the one a subscription added meanwhile replaces: never a stale answer kept
        local = known.get(key)
        if local is None:
            local = bool(keys.cache_size(key)) or any(_intersects(e, key) for e in self._local_exprs)
            if len(known) < MAX_KEYS:
                known[key] = local
        if local:
            return True
        probe = self._probes.get(key)
        if probe is None:
            if len(self._probes) >= MAX_KEYS:
                return True
            probe = self.session.declare_publisher(key, allowed_destination=zenoh.Locality.REMOTE)
            self._probes[key] = probe
            self._resources.append(probe)
        return is_matched(probe)

    @property
    def published_keys(self) -> tuple[str, ...]:
        """The keys this session holds a publisher for (at most :data:`MAX_KEYS`; nothing a client sends adds one)."""
        return tuple(self._publishers.copy())  # copy(): atomic, while a publishing thread may add one

    def wait_matching(self, key: str, timeout: float) -> bool:
        """Wait up to ``timeout`` s until a subscriber of ``key`` is known to this session; returns whether one is.

        A client session drops a put that nobody it knows of listens to, and a subscriber declared a moment
        ago (a sim that has just started: its token and ``srv/world`` can reach a user before its command
        subscription does) is not known yet: a command sent then is lost without a word."""
        pub = self._publisher(key)
        if getattr(pub, "matching_status", None) is None:
            return True  # nothing to ask (a latched key's advanced publisher): put and hope, as before
        return wait_matched([pub], timeout)

    # ------------------------------------------------------------------ authority (fabric.authority_stamp)

    def assume_term(self, term: int, scopes: Iterable[str] = ()) -> None:
        """Stamp ``term`` on everything published from now on, and fence below it in ``scopes`` (the robots and
        objects this authority serves: other sims of the world have terms of their own). The one way to set
        the term; ``stamp`` only reads it, muzzles and watches for freezes."""
        self.stamp.assume_term(term)
        self.sim_fence.raise_to(term, tuple(scopes))

    def connected(self) -> bool:
        """Whether this session can hear anyone now: a router (the embedded profile) always can; a client
        or a peer needs a live link to a router or a peer. False after its link died (the other side
        dropped it while this process was paused) until the session is connected again."""
        if self.config.profile == "embedded":
            return True
        try:
            info = self.session.info
            return bool(list(info.routers_zid()) or list(info.peers_zid()))
        except Exception:  # a closing session
            return False

    def put_raw(self, key: str, payload: bytes) -> None:
        """Put bytes as they are (replay, tools); nothing is checked."""
        self.session.put(key, payload)

    def subscribe(
        self,
        key_expr: str,
        callback: Callable[[str, Any], None],
        *,
        expected: type | tuple[type, ...] | None = None,
        history: bool = False,
        remote_only: bool = False,
    ) -> Any:
        """Call ``callback(key, message)`` for every valid message on ``key_expr``.

        ``history``: first the latest sample of every latched key that matches (published before
        this subscriber existed, by publishers still alive), then live samples as usual.
        ``remote_only``: never this session's own publications (a sim listening for other sims' terms
        on the streams it publishes itself decoded its own ~4,000 messages a second)."""

        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind != zenoh.SampleKind.PUT:
                return
            key = str(sample.key_expr)
            self.counters["received"] += 1
            try:
                msg = decode(sample.payload.to_bytes(), expected)
            except DecodeError as exc:
                self.reports.bad_payload(key, exc, where=key_expr)
                return
            if not self._fence_watch.believe(key, msg):
                return
            try:
                callback(key, msg)
            except Exception:
                self.counters["callback_errors"] += 1
                log.exception("callback for %s failed", key)

        return self.subscribe_raw(key_expr, on_sample, history=history, remote_only=remote_only)

    def subscribe_raw(
        self,
        key_expr: str,
        callback: Callable[[zenoh.Sample], None],
        *,
        history: bool = False,
        remote_only: bool = False,
    ) -> zenoh.Subscriber[None] | LatestThenLive:
        """``callback(sample)`` for every sample, undecoded; ``history`` and ``remote_only`` as in :meth:`subscribe`."""
        sub: zenoh.Subscriber[None] | LatestThenLive
        if remote_only:
            if history:
                raise ValueError("remote_only subscriptions have no history")
            sub = self.session.declare_subscriber(key_expr, callback, allowed_origin=zenoh.Locality.REMOTE)
        elif history:
            # not zenoh's advanced subscriber: it drops live samples that arrive out of timestamp order across
            # one session's publishers (fabric/history.py)
            sub = LatestThenLive(self.session, key_expr, callback)
        else:
            sub = self.session.declare_subscriber(key_expr, callback)
        self.declared.add("subscriber", key_expr, sub)
        if not remote_only:  # kept after an undeclare: listened() then says yes where it could say no, never worse
            self._local_exprs = self._local_exprs | {key_expr}
            self._local_keys = {}  # after the new expression: a check that began before stores into the old map
        self._resources.append(sub)
        return sub

    def _tell_declared(self, query: zenoh.Query) -> None:
        """Answer ``list``/``info``/``ps -v``: what this peer subscribes to and serves now (fabric.declared)."""
        subs, served = self.declared.now()
        key = keys.peer(self.world, self.kind, self.peer_id)
        try:
            query.reply(key, encode_told(Told(self.kind, self.peer_id, subs, served)))
        except Exception:  # a closing session, or an asker the router's access control keeps from the answer
            self.counters["query_errors"] += 1

    # ------------------------------------------------------------------ liveliness

    def live_peers(self, kind: str = "*", *, timeout: float = 1.0) -> list[tuple[str, str]]:
        """(kind, id) of every live peer in this world, from liveliness tokens."""
        out = []
        for key in self.live_tokens(keys.peers_all(self.world, kind), timeout=timeout):
            try:
                p = keys.parse(key)
            except ValueError:  # a token any login may declare that names no peer: not one of ours
                self.counters["bad_tokens"] += 1
                continue
            out.append((p.subject, p.leaf))
        return sorted(set(out))

    def live_tokens(self, key_expr: str, *, timeout: float = 1.0) -> list[str]:
        """The keys of the liveliness tokens alive under ``key_expr`` now, as declared, parsed or not (a launcher
        waiting for a peer's token, an audit listing made-up ones)."""
        return [
            str(rep.ok.key_expr)
            for rep in self.session.liveliness().get(key_expr, timeout=timeout)
            if rep.ok is not None
        ]

    def _on_transport(self, event: zenoh.TransportEvent) -> None:
        if event.kind == zenoh.SampleKind.DELETE:
            self._link_lost_at = time.monotonic()
            self.counters["links_lost"] += 1
            # said: while the link is down this peer's services and streams are gone for everyone (its queries
            # end with "nobody serves it"); a process starved past its lease loses its link this way
            log.warning(
                "%s %s: lost its link to the router (the router went, or no word crossed it for a lease: %.1f s); "
                "reconnecting",
                self.kind,
                self.peer_id,
                self.config.lease_ms / 1000.0,
            )
        elif self._link_lost_at != float("-inf"):
            self._link_back_at = time.monotonic()
            # a link back after one was lost (the first one is not news), said at the loss's level: who read
            # "reconnecting" learns it did, and when (the paused student's log had the loss and never the link back)
            log.warning(
                "%s %s: linked to the router again, %.1f s after losing its link",
                self.kind,
                self.peer_id,
                time.monotonic() - self._link_lost_at,
            )

    def link_changed_at(self) -> float:
        """When this client last lost its link to the router or had it back (monotonic s; -inf if never): a change
        since one last looked means what was sent to it meanwhile may be lost with the old link (an authority then
        gives every owner a whole lease to renew: ownership.state)."""
        return max(self._link_lost_at, self._link_back_at)

    def relinked_within(self, seconds: float) -> bool:
        """Whether this client lost its link to the router, or had it back, within the last ``seconds``: what it
        hears then may be the link's doing, not the world's (every token it knew goes with the old link, and zenoh
        may tell those goings after the new link's tokens). Never for a router or a peer (no link of theirs is
        lost so)."""
        return time.monotonic() - self.link_changed_at() <= seconds

    def _linked(self) -> bool:
        """Whether this client has a link to a router now (it reconnects by itself after losing it)."""
        try:
            return any(True for _ in self.session.info.routers_zid())
        except Exception:  # a closed session: nothing to wait for
            return True

    def watch_peers(self, callback: Callable[[str, str, bool], None], kind: str = "*") -> TokenWatch:
        """``callback(kind, id, alive)`` on every token that appears or goes (existing ones first; a going checked
        with the router: :mod:`fabric.token_watch`; every going of a sim, see :meth:`watch_tokens`)."""

        def on_token(key: str, alive: bool) -> None:
            try:
                p = keys.parse(key)
            except ValueError:
                return
            callback(p.subject, p.leaf, alive)

        return self.watch_tokens(keys.peers_all(self.world, kind), on_token, every_going=kind == "sim")

    def watch_tokens(
        self, key_expr: str, callback: Callable[[str, bool], None], *, every_going: bool = False
    ) -> TokenWatch:
        """``callback(key, alive)`` on every liveliness token under ``key_expr`` that appears or goes (existing ones
        first), its key as declared, parsed or not (a recorder keeps every token it hears, a made-up one too). A
        going is checked with the router, so a link that came back in another order ends with the token there
        (:mod:`fabric.token_watch`): one heard about a loss of this session's link, or with ``every_going`` any
        (sims' tokens: a live sim held for gone has its every sample refused, :mod:`fabric.token_watch`)."""

        def told(key: str, alive: bool) -> None:
            if not alive:
                self._token_gone_at = time.monotonic()
            callback(key, alive)

        watch = TokenWatch(
            self.session, key_expr, told, link_lost_at=None if every_going else lambda: self._link_lost_at
        )
        self._resources.append(watch)
        return watch


def shutdown_event(signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM)) -> threading.Event:
    """An event set on SIGINT/SIGTERM, so a peer's loop can end cleanly and close its session.

    Only the main thread can install handlers; elsewhere the event simply never fires by signal.
    """
    ev = threading.Event()
    if threading.current_thread() is threading.main_thread():
        for s in signals:
            signal.signal(s, lambda *_: ev.set())
    return ev


def _intersects(expr: str, key: str) -> bool:
    """Whether key expression ``expr`` takes ``key`` (one of this session's subscriptions; a made-up one says no)."""
    try:
        return bool(zenoh.KeyExpr(expr).intersects(zenoh.KeyExpr(key)))
    except Exception:
        return False
