"""A lane: answers that must not hold up zenoh's callback thread, served on a worker of their own, in turn.

Everything a peer receives on one link comes through one zenoh callback thread, in order: a query
answered there makes every renewal, command and query behind it wait. A :class:`Lane` takes such work
(ownership requests, whole-world snapshots) off that thread: one worker serves the askers' queues in
turn (round robin), so one asker's backlog delays another's answer by at most one job of each other
asker. Each asker's queue and the whole lane are bounded: :meth:`Lane.submit` says False when full,
and the caller refuses the ask at once.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from typing import Callable

log = logging.getLogger("robofabric")

__all__ = ["Lane"]


class Lane:
    """One daemon worker running the askers' jobs in turn; ``per_asker`` and ``total`` bound what waits."""

    def __init__(self, name: str, *, per_asker: int = 8, total: int = 256) -> None:
        self.name = name
        self.per_asker = per_asker
        self.total = total
        self._queues: dict[str, deque[Callable[[], None]]] = {}  # insertion order is the turn order
        self._waiting = 0
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=f"lane-{name}", daemon=True)
        self._thread.start()

    def submit(self, asker: str, job: Callable[[], None]) -> bool:
        """Queue ``job`` for ``asker``; False (nothing queued) when her queue or the lane is full, or closed."""
        with self._cond:
            queue = self._queues.get(asker)
            if self._closed or self._waiting >= self.total or (queue is not None and len(queue) >= self.per_asker):
                return False
            if queue is None:
                queue = self._queues[asker] = deque()
            queue.append(job)
            self._waiting += 1
            self._cond.notify()
            return True

    def waiting(self) -> int:
        with self._cond:
            return self._waiting

    def _next(self) -> Callable[[], None] | None:
        with self._cond:
            while not self._waiting and not self._closed:
                self._cond.wait()
            if self._closed:
                return None
            asker = next(iter(self._queues))
            queue = self._queues.pop(asker)
            job = queue.popleft()
            if queue:
                self._queues[asker] = queue  # to the back of the turn
            self._waiting -= 1
            return job

    def _run(self) -> None:
        while True:
            job = self._next()
            if job is None:
                return
            try:
                job()
            except Exception:  # one asker's trouble must not end the lane
                log.exception("lane %s: a job failed", self.name)
            job = None  # what it holds (a query to answer) goes now, not when the next job comes

    def close(self) -> None:
        """No more jobs (those waiting are dropped: their askers time out); idempotent."""
        with self._cond:
            self._closed = True
            self._queues.clear()
            self._waiting = 0
            self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
