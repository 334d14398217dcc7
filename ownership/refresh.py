"""Ask for every record again, on demand, at most one asker at a time.

A user's replica asks the authorities for every record when a new sim appears or a sim it has not heard
from speaks (its first records may have been refused before its token arrived). Made-up sim tokens and
forged records can make many such occasions; :class:`Refresher` turns them into at most one running
thread that runs its job once more for every burst of asks that came while it ran, never a thread each.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

log = logging.getLogger("robofabric.ownership")


class Refresher:
    """Runs ``job`` on a thread of its own when asked, once it is enabled and until it is closed."""

    def __init__(self, job: Callable[[], None], *, name: str) -> None:
        self._job = job
        self._name = name
        self._lock = threading.Lock()
        self._enabled = False
        self._closed = False
        self._running = False
        self._again = False

    def enable(self) -> None:
        """From now on an ask runs the job (before it, asks are ignored: the first query is under way)."""
        with self._lock:
            self._enabled = True

    def ask(self) -> None:
        """Run the job once more: on a new thread when none runs, else by the running one when it is done."""
        with self._lock:
            if not self._enabled or self._closed:
                return
            self._again = True
            if self._running:
                return
            self._running = True
        threading.Thread(target=self._run, name=self._name, daemon=True).start()

    def _run(self) -> None:
        while True:
            with self._lock:
                if not self._again or self._closed:
                    self._running = False
                    return
                self._again = False
            try:
                self._job()
            except Exception:  # a closing session
                log.debug("refresh after a new sim failed", exc_info=True)

    def close(self) -> None:
        """No more runs; one under way finishes its job."""
        with self._lock:
            self._closed = True


__all__ = ["Refresher"]
