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
  sample whose cache reply came first (the same timestamp: the same publication) is not delivered twice.
"""

from __future__ import annotations

import threading
from typing import Any, Callable

import zenoh

from fabric import keys

__all__ = ["LatestThenLive", "cache_selector", "MAX_TRACKED"]

MAX_TRACKED = 1024
"""Latched keys whose newest timestamp a subscription keeps; beyond, a cached value is always delivered."""
HISTORY_TIMEOUT = 5.0
"""Seconds a cache query may take (a cache answers from memory: this is for a loaded machine)."""


def cache_selector(key_expr: str) -> str:
    """The key expression of the caches (and publisher tokens) of every advanced publisher in ``key_expr``.

    ``@adv`` is a verbatim chunk: ``**`` never matches it, so it is named."""
    return f"{key_expr}/@adv/pub/**"


class LatestThenLive:
    """``callback(sample)`` for every live sample on ``key_expr``, and for the latest cached one of each
    latched key. Declared on construction; ``undeclare()`` takes it all away (idempotent)."""

    def __init__(self, session: zenoh.Session, key_expr: str, callback: Callable[[zenoh.Sample], None]) -> None:
        self._session = session
        self._callback = callback
        self._lock = threading.Lock()
        self._newest: dict[str, Any] = {}
        self._is_latched: dict[str, bool] = {}
        self._closed = False
        self.stale = 0
        """Cached values not delivered because a newer one of their key already was."""
        self.duplicates = 0
        """Live samples not delivered because their cache's reply (the same publication) already was."""
        self._resources: list[Any] = [session.declare_subscriber(key_expr, self._on_live)]
        caches = cache_selector(key_expr)
        # late publishers: a token that appears after this point gets its own cache asked
        self._resources.append(session.liveliness().declare_subscriber(caches, self._on_token))
        self._ask(caches)  # every cache there now (one asked twice in between: its value is not newer)

    # ------------------------------------------------------------------ delivering

    def _latched(self, key: str) -> bool:
        """``keys.is_latched(key)``, remembered for :data:`MAX_TRACKED` keys (a parse costs ~3 µs a sample)."""
        latched = self._is_latched.get(key)
        if latched is None:
            latched = keys.cache_size(key) > 0  # latched keys, and events kept for a link that was down
            if len(self._is_latched) < MAX_TRACKED:
                self._is_latched[key] = latched
        return latched

    def _on_live(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        if not self._latched(key):
            self._callback(sample)  # streams: no lock, no bookkeeping
            return
        with self._lock:  # a latched key: a history reply must not overtake or follow it back in time
            stamp = sample.timestamp
            if stamp is not None and self._newest.get(key) == stamp:
                self.duplicates += 1  # its cache's reply came first: the same publication, delivered once
                return
            self._note(key, stamp)
            self._callback(sample)

    def _on_reply(self, reply: zenoh.Reply) -> None:
        sample = reply.ok
        if sample is None or self._closed:
            return
        key = str(sample.key_expr)
        with self._lock:
            if not self._note(key, sample.timestamp):
                self.stale += 1
                return
            self._callback(sample)

    def _note(self, key: str, stamp: Any) -> bool:
        """Record ``stamp`` as ``key``'s newest if it is newer; whether it was (called with the lock held)."""
        if stamp is None:
            return True  # a session without timestamps: nothing to compare, deliver
        last = self._newest.get(key)
        if last is not None and not last < stamp:
            return False
        if last is not None or len(self._newest) < MAX_TRACKED:
            self._newest[key] = stamp
        return True

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
