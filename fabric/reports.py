"""A peer's reports of what went wrong: events published and logged, bad input counted, floods held down.

Every report (a log line and an event under ``rf/{world}/event/...``) of one kind goes out at most
:data:`REPORT_BURST` times per :data:`REPORT_INTERVAL` seconds; the rest are counted, and the next one says how
many were suppressed. Kinds are keyed by fixed words, never client text, so a flood on made-up keys is a few
reports per interval and grows no memory. A :class:`~fabric.session.Fabric` holds one as ``fabric.reports``.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

from fabric import keys
from fabric.interfaces import Event, EventKind, Header
from fabric.limits import RateLimiter, clip

log = logging.getLogger("robofabric")

REPORT_INTERVAL = 5.0
REPORT_BURST = 5
"""Reports (log line + event) of bad input per subscription or reason per :data:`REPORT_INTERVAL` seconds;
the rest are counted and the next report says how many were suppressed."""

__all__ = ["Reports", "REPORT_INTERVAL", "REPORT_BURST"]


class Reports:
    """Thread-safe. ``publish(key, message)`` and ``header(key)`` are the session's; ``reporter()`` names this peer
    in the key of its decode reports (``event/decode/by/{login}``: a router lets each login write only its own),
    asked only when one goes out (it reads the login from the zenoh config file)."""

    def __init__(
        self,
        world: str,
        *,
        counters: Any,
        publish: Callable[[str, Any], Any],
        header: Callable[[str], Header],
        reporter: Callable[[], str],
    ) -> None:
        self._world = world
        self._counters = counters
        self._publish = publish
        self._header = header
        self._reporter = reporter
        self._lock = threading.Lock()
        self.interval = REPORT_INTERVAL
        self._limiter = RateLimiter(REPORT_INTERVAL, burst=REPORT_BURST, max_keys=256)

    def should_report(self, key: str) -> int | None:
        """Rate limit for reports about ``key`` (a fixed reason, never client text): ``None`` to stay
        quiet, else the number of reports suppressed since the last one."""
        with self._lock:
            verdict = self._limiter.check(key, time.monotonic())
        if not verdict.report:
            self._counters["reports_suppressed"] += 1
            return None
        return verdict.suppressed

    def emit(self, event: Event, *parts: str, limit: str | None = None) -> None:
        """Publish an event on ``rf/{world}/event/{parts...}`` and log it.

        ``limit``: a key (never client text) under which this kind of event is published and logged
        at most :data:`REPORT_BURST` times per :attr:`interval`; the next one says how many were suppressed."""
        if limit is not None:
            suppressed = self.should_report(limit)
            if suppressed is None:
                return
            if suppressed:
                event = Event(
                    kind=event.kind,
                    reason=event.reason,
                    object=event.object,
                    user=event.user,
                    severity=event.severity,
                    data={**event.data, "suppressed": suppressed},
                    header=event.header,
                )
        level = {"debug": logging.DEBUG, "info": logging.INFO, "warning": logging.WARNING, "error": logging.ERROR}
        more = f" ({event.data['suppressed']} more like it suppressed)" if event.data.get("suppressed") else ""
        log.log(
            level.get(event.severity, logging.INFO), "%s %s: %s%s", event.kind, event.object or "", event.reason, more
        )
        try:
            self._publish(keys.event(self._world, *(parts or (event.kind,))), event)
        except Exception as exc:  # a closing session must not turn an event into a crash
            log.debug("could not publish event: %s", exc)

    def bad_payload(self, key: str, exc: Exception, *, where: str) -> None:
        """Count a payload that could not be used; report it at most a few times per ``where`` per interval.

        ``where`` is what the peer subscribed to (a fixed key expression), never the concrete key: a
        flood on made-up keys under one wildcard is a few reports per interval, not one per key. The
        check comes first: a suppressed report costs a counter and a lock, nothing is built for it."""
        self._counters["decode_errors"] += 1
        suppressed = self.should_report(f"decode:{where}")
        if suppressed is None:
            return
        data: dict[str, Any] = {"key": clip(key), "subscription": clip(where)}
        if suppressed:
            data["suppressed"] = suppressed
        self.emit(
            Event(
                kind=EventKind.DECODE_ERROR,
                reason=clip(str(exc)),
                severity="warning",
                data=data,
                header=self._header("event"),
            ),
            keys.DECODE,
            keys.BY,
            self._reporter(),
        )
