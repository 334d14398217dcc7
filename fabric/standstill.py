"""When this process last stood still: paused (SIGSTOP, a laptop's lid closed) or starved for over a second.

A client woken from a pause past its lease finds its link closed by the router, but learns it only a moment after
it wakes, on zenoh's threads. A query its program asks in that moment meets "nobody serves it" at once, and nothing
in the session says why yet: CI's paused student (2026-12-01) asked for his plan as he woke, was told at once that
nobody serves it, and his link's loss was told a few milliseconds later. :class:`Standstill` is a thread that ticks
every :data:`TICK_S` and notes each gap longer than :data:`GAP_S` between two ticks: the process did not run then.
:mod:`fabric.rpc` waits to hear whether the link closed under a query that found nobody at once during or just
after such a gap, as it does after a liveliness token went.

The decision (:meth:`Standstill.tick`, :meth:`Standstill.last`) takes its time from the clock it is given; the
thread only calls ``tick``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

__all__ = ["GAP_S", "TICK_S", "Standstill"]

TICK_S = 0.1
"""How often the thread ticks (ten wake-ups a second: nothing next to a session's own threads)."""
GAP_S = 1.0
"""A gap between two ticks longer than this is a standstill: ten ticks missed, well past a busy box's scheduling."""


class Standstill:
    """The latest standstill of this process, from a ticking thread (``thread=False``: the caller ticks)."""

    def __init__(
        self,
        clock: Callable[[], float] = time.monotonic,
        *,
        tick_s: float = TICK_S,
        gap_s: float = GAP_S,
        thread: bool = True,
    ) -> None:
        self._clock, self._tick_s, self._gap_s = clock, tick_s, gap_s
        self._tick_at = clock()
        self._since = self._until = float("-inf")
        self._stop = threading.Event()
        if thread:
            threading.Thread(target=self._run, name="standstill", daemon=True).start()

    def tick(self) -> None:
        """One tick: a gap since the last one longer than ``gap_s`` is noted as the latest standstill."""
        now = self._clock()
        if now - self._tick_at > self._gap_s:
            self._since, self._until = self._tick_at, now
        self._tick_at = now

    def last(self) -> tuple[float, float]:
        """(since, until) of the latest standstill (-inf, -inf: none). One going on as far as the ticks know (the
        thread has not ticked since the process woke: the caller ran first) ends now."""
        now = self._clock()
        if now - self._tick_at > self._gap_s:
            return self._tick_at, now
        return self._since, self._until

    def undeclare(self) -> None:
        """End the thread (a session's resource: closed with it)."""
        self._stop.set()

    def _run(self) -> None:
        while not self._stop.wait(self._tick_s):
            self.tick()
