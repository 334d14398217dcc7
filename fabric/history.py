"""A stream with a late joiner's latest values, and nothing lost or reordered.

zenoh's advanced subscriber (``zenoh.ext``, ``HistoryConfig(detect_late_publishers=True)``) gives the
latest value of every cached publisher, but it also filters the live stream: a sample with no sequence
number (every stream the fabric publishes: poses, joints, scans) is ordered by its timestamp across all
the publishers of one session, and one that arrives after a later one of another key is dropped without
a word. Measured on ``rf/W/robot/base1/*`` of a running sim: 471 of 500 poses, where a plain subscriber
got 499; a live ROS 2 recording lost 603 of 3,000 poses in a minute (issue 32).

:class:`LatestThenLive` keeps the two jobs apart:

- a plain subscriber delivers every live sample, in the order it arrives;
- the latest value of every latched key (:func:`fabric.keys.is_latched`) comes from its publisher's
  cache (``{key}/@adv/pub/{zid}/{eid}/_``, the queryable and token an advanced publisher with a cache
  declares): once for the publishers there at the start, and again for each one that appears later (a
  publisher that started later, or a link that came back) by its liveliness token;
- a cache that keeps several samples of a key (the ownership records and events of
  :func:`fabric.keys.cache_size`) gives them all, oldest first: a subscriber whose link was down gets those it
  missed;
- a cached value of a latched key or an ownership record is delivered only when it is newer (its timestamp)
  than every value of that key delivered so far, so a history reply that arrives after a live sample never takes
  the key back; a live sample whose cache reply came first (the same publication) is not delivered twice;
- nor is a live sample of a latched key older than one its publisher's clock stamped before: a joiner's cache
  reply can overtake the
  publications still on their way to it (a goal put 1, 2, 3 as a viewer joined reached it as 1, then 3 from the
  cache, then 2 live, and was left at 2: the grouped suite's run of 2026-11-30);
- an event (``event/own/*``, ``event/reject/*``) is news, each one: delivered once, whichever way it comes first,
  even when it is older than one delivered. One missed while the link was down comes from the cache when the link
  is back, often after a newer one live (:func:`verdict`).
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any, Callable, Collection

import zenoh

from fabric import keys

__all__ = ["LatestThenLive", "Ledger", "cache_selector", "keeping", "same_clock", "verdict", "MAX_TRACKED"]

MAX_TRACKED = 1024
"""Latched keys whose newest timestamp a subscription keeps; beyond, a cached value is always delivered."""
HISTORY_TIMEOUT = 5.0
"""Seconds a cache query may take (a cache answers from memory: this is for a loaded machine)."""
ASK_AGAIN_S = (1.0, 3.0, 10.0)
"""When a publisher's cache, asked as its token appeared, answered nothing, it is asked again after these delays. A
link that came back brings the token first and the cache's route after it, or the answer past the timeout at load:
the soak's observer, back across its router's restart, was asked nothing it had missed (a whole run of
2026-12-01). A publisher whose cache holds nothing costs three queries more."""


def cache_selector(key_expr: str) -> str:
    """The key expression of the caches (and publisher tokens) of every advanced publisher in ``key_expr``.

    ``@adv`` is a verbatim chunk: ``**`` never matches it, so it is named."""
    return f"{key_expr}/@adv/pub/**"


def keeping(key: str) -> str:
    """How a subscription treats ``key``'s samples: ``""`` a stream (every sample, no bookkeeping); ``"latest"`` a
    latched key (its newest value); ``"records"`` an ownership record's key (several kept; the newest wins, an
    older one live is the replica's to judge by its epoch); ``"news"`` an ownership or reject event's key (several
    kept, each one news: delivered once, in whatever order it comes)."""
    kept = keys.cache_size(key)
    if not kept:
        return ""
    if kept == 1:
        return "latest"
    return "news" if keys.parse(key).category == "event" else "records"


def same_clock(a: Any, b: Any) -> bool:
    """Whether two stamps come from one publisher's clock (a zenoh timestamp's id; stamps without one, as in a test's
    integers, count as one clock): only such stamps say which of two live samples is older. Two machines' clocks are
    never compared for that: a class's laptops differ by seconds, and arrival is the order there."""
    ida, idb = getattr(a, "get_id", None), getattr(b, "get_id", None)
    if ida is None or idb is None:
        return ida is idb
    return bool(ida() == idb())


def verdict(keep: str, newest: Any, stamp: Any, *, live: bool, seen: Collection[Any] = ()) -> str:
    """What a subscription does with one sample of a kept key (``keep``: :func:`keeping`'s word): ``newest`` the
    newest stamp it delivered of that key (None: none yet, or not tracked), ``seen`` the stamps it delivered of it
    lately (a record's from its cache, an event's all), ``stamp`` the sample's (None: a session without timestamps).
    ``"deliver"``, ``"duplicate"`` (a live sample delivered already from its cache: the same publication) or
    ``"stale"`` (a cached one older than one delivered, or delivered already; a live latest value older than one
    delivered).

    An event missed while the link was down comes from its publisher's cache when the link is back, often after a
    newer one live: it is delivered all the same (a soak's router restart lost s01's "released: left" that way, after
    her "owner again" came live). A latched key is a latest value: one older than the one shown, by the same publisher's clock,
    would take it back; another publisher's live value is newer by arrival, whatever its clock says."""
    if stamp is None or newest is None:
        return "deliver"
    if stamp == newest or stamp in seen:
        return "duplicate" if live else "stale"
    if newest < stamp or keep == "news":
        return "deliver"
    if live and (keep == "records" or not same_clock(newest, stamp)):
        return "deliver"  # a record is the replica's to judge; a latest value from another clock came later here
    return "stale"


class Ledger:
    """What one subscription delivered of its kept keys: each key's newest stamp, and the stamps it delivered lately
    (a record key's from its cache, whose live copies may still be on their way; an event key's all). Pure: the
    caller holds a lock. Tracks :data:`MAX_TRACKED` keys; beyond, every sample of another key is delivered."""

    def __init__(self) -> None:
        self.newest: dict[str, Any] = {}
        self.seen: dict[str, deque[Any]] = {}

    def offer(self, key: str, stamp: Any, keep: str, *, live: bool) -> str:
        """:func:`verdict` on one sample of ``key``, noted when it is delivered."""
        last = self.newest.get(key)
        seen = self.seen.get(key)
        said = verdict(keep, last, stamp, live=live, seen=seen or ())
        if said == "deliver" and keep == "news" and not live and seen is not None and len(seen) == seen.maxlen:
            if stamp is not None and stamp < min(seen):
                said = "stale"  # older than all it remembers delivering: taken for one delivered long ago
        if said != "deliver" or stamp is None:
            return said
        if last is None or last < stamp:
            if last is not None or len(self.newest) < MAX_TRACKED:
                self.newest[key] = stamp
        if (keep == "news" or (keep == "records" and not live)) and (seen is not None or len(self.seen) < MAX_TRACKED):
            if seen is None:
                seen = self.seen[key] = deque(maxlen=2 * keys.KEPT_EVENTS)
            seen.append(stamp)
        return said


class LatestThenLive:
    """``callback(sample)`` for every live sample on ``key_expr``, and for the latest cached one of each
    latched key. Declared on construction; ``undeclare()`` takes it all away (idempotent)."""

    def __init__(self, session: zenoh.Session, key_expr: str, callback: Callable[[zenoh.Sample], None]) -> None:
        self._session = session
        self._callback = callback
        self._lock = threading.Lock()
        self._ledger = Ledger()
        self._keeping: dict[str, str] = {}  # by key: keeping(key)
        self._closed = False
        self.stale = 0
        """Cached values, and live values of a latched key, not delivered because a newer one of their key already was."""
        self.duplicates = 0
        """Live samples not delivered because their cache's reply (the same publication) already was."""
        self.asked = 0
        """Cache queries made (a test waits on it)."""
        self._resources: list[Any] = [session.declare_subscriber(key_expr, self._on_live)]
        caches = cache_selector(key_expr)
        # late publishers: a token that appears after this point gets its own cache asked
        self._resources.append(session.liveliness().declare_subscriber(caches, self._on_token))
        self._ask(caches)  # every cache there now (one asked twice in between: its value is not newer)

    # ------------------------------------------------------------------ delivering

    def _keep(self, key: str) -> str:
        """:func:`keeping`, remembered for :data:`MAX_TRACKED` keys (a parse costs ~3 µs a sample)."""
        keep = self._keeping.get(key)
        if keep is None:
            try:
                keep = keeping(key)
            except ValueError:  # not a robofabric key: a stream
                keep = ""
            if len(self._keeping) < MAX_TRACKED:
                self._keeping[key] = keep
        return keep

    def _on_live(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        keep = self._keep(key)
        if not keep:
            self._callback(sample)  # streams: no lock, no bookkeeping
            return
        with self._lock:  # a kept key: a history reply must not overtake it, follow it back in time or repeat it
            self._offer(key, sample, keep, live=True)

    def _on_reply(self, reply: zenoh.Reply) -> None:
        sample = reply.ok
        if sample is None or self._closed:
            return
        key = str(sample.key_expr)
        with self._lock:
            self._offer(key, sample, self._keep(key), live=False)

    def _offer(self, key: str, sample: zenoh.Sample, keep: str, *, live: bool) -> None:
        """Deliver ``sample`` as the ledger says (called with the lock held)."""
        said = self._ledger.offer(key, sample.timestamp, keep, live=live)
        if said == "duplicate":
            self.duplicates += 1
        elif said == "stale":
            self.stale += 1
        else:
            self._callback(sample)

    # ------------------------------------------------------------------ asking caches

    def _on_token(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT and not self._closed:
            self._ask(str(sample.key_expr), ASK_AGAIN_S)

    def _ask(self, selector: str, again: tuple[float, ...] = ()) -> None:
        """Ask the caches in ``selector``; when none answered, again after ``again[0]`` s (then the rest)."""
        answered = [0]

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                answered[0] += 1
            self._on_reply(reply)

        def done() -> None:
            if answered[0] or not again or self._closed:
                return
            timer = threading.Timer(again[0], self._ask, args=(selector, again[1:]))
            timer.daemon = True
            timer.start()

        self.asked += 1
        try:
            # the cache replies on the publication's own key, not on the one asked: accept any; and every sample a
            # cache keeps (kept events: several of one key), oldest first, not only the latest of each key
            self._session.get(
                selector,
                zenoh.handlers.Callback(on_reply, done),
                accept_replies=zenoh.ReplyKeyExpr.ANY,
                timeout=HISTORY_TIMEOUT,
                consolidation=zenoh.ConsolidationMode.NONE,
            )
        except Exception:  # a closing session
            pass

    @property
    def undeclared(self) -> bool:
        """Whether :meth:`undeclare` was called (a peer tells only what it still subscribes to: fabric.declared)."""
        return self._closed

    def undeclare(self) -> None:
        """Stop delivering; safe to call twice and after the session closed."""
        self._closed = True
        resources, self._resources = self._resources, []
        for res in reversed(resources):
            try:
                res.undeclare()
            except Exception:  # already gone with a closing session
                pass
