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
- a cached value is delivered only when it is newer (its timestamp) than every value of that key
  delivered so far, so a history reply that arrives after a live sample never takes the key back; a live
  sample whose cache reply came first (the same timestamp: the same publication) is not delivered twice;
- nor does a live sample of a latched key (a latest value, not a kept event or record) that is older than one
  delivered: a joiner's cache reply can overtake the publications still on their way to it (a goal put 1, 2, 3 as alice's viewer joined reached it
  as 1, then 3 from the cache, then 2 live: its goal was left at 2, the grouped suite's run of 2026-11-30).
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any, Callable, Collection

import zenoh

from fabric import keys

__all__ = ["LatestThenLive", "Ledger", "cache_selector", "verdict", "MAX_TRACKED"]

MAX_TRACKED = 1024
"""Latched keys whose newest timestamp a subscription keeps; beyond, a cached value is always delivered."""
HISTORY_TIMEOUT = 5.0
"""Seconds a cache query may take (a cache answers from memory: this is for a loaded machine)."""


def cache_selector(key_expr: str) -> str:
    """The key expression of the caches (and publisher tokens) of every advanced publisher in ``key_expr``.

    ``@adv`` is a verbatim chunk: ``**`` never matches it, so it is named."""
    return f"{key_expr}/@adv/pub/**"


def verdict(kept: int, newest: Any, stamp: Any, *, live: bool, cached: Collection[Any] = ()) -> str:
    """What a subscription does with one sample of a key whose publisher keeps ``kept`` (> 0) samples: ``newest`` the
    newest stamp it delivered of that key (None: none yet, or not tracked), ``cached`` the stamps its cache's replies
    delivered, ``stamp`` the sample's (None: a session without timestamps). ``"deliver"``, ``"duplicate"`` (a live
    sample whose cache's reply came first: the same publication) or ``"stale"`` (older than one delivered: a cached
    value always, a live one of a latched key).

    A kept event or record older than one delivered is still news, live: another publisher's, or the ownership
    replica's to judge by its epoch. A latched key is a latest value: one older than the one shown takes it back."""
    if stamp is None or newest is None:
        return "deliver"
    if live and (stamp == newest or stamp in cached):
        return "duplicate"
    if newest < stamp:
        return "deliver"
    return "stale" if not live or kept == 1 else "deliver"


class Ledger:
    """What one subscription delivered of its kept keys: each key's newest stamp, and the stamps its cache's replies
    gave of a key that keeps several (their live copies may still be on their way). Pure: the caller holds a lock.
    Tracks :data:`MAX_TRACKED` keys; beyond, every sample of another key is delivered."""

    def __init__(self) -> None:
        self.newest: dict[str, Any] = {}
        self.cached: dict[str, deque[Any]] = {}

    def offer(self, key: str, stamp: Any, kept: int, *, live: bool) -> str:
        """:func:`verdict` on one sample of ``key``, noted when it is delivered."""
        last = self.newest.get(key)
        cached = self.cached.get(key, ())
        said = verdict(kept, last, stamp, live=live, cached=cached)
        if said != "deliver" or stamp is None:
            return said
        if last is None or last < stamp:
            if last is not None or len(self.newest) < MAX_TRACKED:
                self.newest[key] = stamp
        if not live and kept > 1 and (cached or len(self.cached) < MAX_TRACKED):
            self.cached.setdefault(key, deque(maxlen=kept)).append(stamp)
        return said


class LatestThenLive:
    """``callback(sample)`` for every live sample on ``key_expr``, and for the latest cached one of each
    latched key. Declared on construction; ``undeclare()`` takes it all away (idempotent)."""

    def __init__(self, session: zenoh.Session, key_expr: str, callback: Callable[[zenoh.Sample], None]) -> None:
        self._session = session
        self._callback = callback
        self._lock = threading.Lock()
        self._ledger = Ledger()
        self._kept: dict[str, int] = {}  # by key: how many samples its publisher's cache keeps
        self._closed = False
        self.stale = 0
        """Cached values, and live values of a latched key, not delivered because a newer one of their key already was."""
        self.duplicates = 0
        """Live samples not delivered because their cache's reply (the same publication) already was."""
        self._resources: list[Any] = [session.declare_subscriber(key_expr, self._on_live)]
        caches = cache_selector(key_expr)
        # late publishers: a token that appears after this point gets its own cache asked
        self._resources.append(session.liveliness().declare_subscriber(caches, self._on_token))
        self._ask(caches)  # every cache there now (one asked twice in between: its value is not newer)

    # ------------------------------------------------------------------ delivering

    def _kept_samples(self, key: str) -> int:
        """``keys.cache_size(key)``, remembered for :data:`MAX_TRACKED` keys (a parse costs ~3 µs a sample): 1 on a
        latched key, more on the ownership records and the events kept for a link that was down, 0 on a stream."""
        kept = self._kept.get(key)
        if kept is None:
            kept = keys.cache_size(key)
            if len(self._kept) < MAX_TRACKED:
                self._kept[key] = kept
        return kept

    def _on_live(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        kept = self._kept_samples(key)
        if not kept:
            self._callback(sample)  # streams: no lock, no bookkeeping
            return
        with self._lock:  # a latched key: a history reply must not overtake or follow it back in time
            self._offer(key, sample, kept, live=True)

    def _on_reply(self, reply: zenoh.Reply) -> None:
        sample = reply.ok
        if sample is None or self._closed:
            return
        key = str(sample.key_expr)
        with self._lock:
            self._offer(key, sample, self._kept_samples(key), live=False)

    def _offer(self, key: str, sample: zenoh.Sample, kept: int, *, live: bool) -> None:
        """Deliver ``sample`` as the ledger says (called with the lock held)."""
        said = self._ledger.offer(key, sample.timestamp, kept, live=live)
        if said == "duplicate":
            self.duplicates += 1
        elif said == "stale":
            self.stale += 1
        else:
            self._callback(sample)

    # ------------------------------------------------------------------ asking caches

    def _on_token(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT and not self._closed:
            self._ask(str(sample.key_expr))

    def _ask(self, selector: str) -> None:
        try:
            # the cache replies on the publication's own key, not on the one asked: accept any; and every sample a
            # cache keeps (kept events: several of one key), oldest first, not only the latest of each key
            self._session.get(
                selector,
                self._on_reply,
                accept_replies=zenoh.ReplyKeyExpr.ANY,
                timeout=HISTORY_TIMEOUT,
                consolidation=zenoh.ConsolidationMode.NONE,
            )
        except Exception:  # a closing session
            pass

    def undeclare(self) -> None:
        """Stop delivering; safe to call twice and after the session closed."""
        self._closed = True
        resources, self._resources = self._resources, []
        for res in reversed(resources):
            try:
                res.undeclare()
            except Exception:  # already gone with a closing session
                pass
