"""Wait until a subscriber matches a publisher: the one way the fabric, its tools and benchmarks do it.

A client session drops a put that nobody it knows of listens to, and a subscriber declared a moment
ago is not known at once: a message sent then is lost without a word. zenoh tells a publisher when its
matching status changes (a matching listener), so the wait sleeps until it changes or time is up,
instead of asking again and again.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Iterable

__all__ = ["is_matched", "wait_matched"]

STOP_CHECK_S = 0.1
"""How often a wait given a ``stop`` event looks at it (a matching change wakes it at once)."""


def is_matched(publisher: Any) -> bool:
    """Whether a subscriber listens to ``publisher`` now. zenoh.ext's advanced publishers (latched keys) do
    not say: False (a MatchingStatus object is always truthy: it is its ``.matching`` that answers)."""
    status = getattr(publisher, "matching_status", None)
    return bool(getattr(status, "matching", False))


def wait_matched(
    publishers: Iterable[Any],
    timeout: float,
    *,
    every: bool = False,
    stop: threading.Event | None = None,
) -> bool:
    """Wait up to ``timeout`` s until a subscriber matches any of ``publishers`` (each of them with
    ``every``); returns whether it did. ``stop`` ends the wait early (False)."""
    pubs = list(publishers)

    def matched() -> bool:
        flags = [is_matched(p) for p in pubs]
        return bool(flags) and (all(flags) if every else any(flags))

    if matched():
        return True
    changed = threading.Event()
    listeners = [
        p.declare_matching_listener(lambda _status: changed.set())
        for p in pubs
        if hasattr(p, "declare_matching_listener")
    ]
    try:
        deadline = time.monotonic() + timeout
        while True:
            changed.clear()
            if matched():
                return True
            left = deadline - time.monotonic()
            if left <= 0 or (stop is not None and stop.is_set()):
                return False
            changed.wait(left if stop is None else min(left, STOP_CHECK_S))
    finally:
        for listener in listeners:
            try:
                listener.undeclare()
            except Exception:  # a session closing under the wait took it already
                pass
