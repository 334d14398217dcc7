"""One clock for every page's redraw, so that what pages share is computed once per tick.

Each page used to redraw on a timer of its own, started when it logged in: twenty timers at twenty phases,
each reading the world a little later than the one before, so no two pages held the same newest pose and
nothing could be shared between them. One ticker calls every page in turn, one after another in one pass of
the event loop: the pages read the same samples, and :class:`~user_peer.console.feed.Decoded` and the view's
drawing cache (:func:`user_peer.console.topview.robot_svg`) do the work once per tick for all of them.

The clock's own pass (:meth:`Ticker.run`) lets the event loop turn between two pages: a pass over a class of 32
took 1-4 s on a loaded 2-core box, and as one call of the loop it held every socket's ping, key and click that
long. Between two pages the loop answers them; a page that left during the pass is not redrawn.

What the pages share needs them to hold the same samples, and a pass that lets the loop turn lasts longer than the
sim's 20 ms between two poses of a robot: the pages redrawn late in the pass had newer bytes than the first, so
every page decoded and drew every robot again (pages x robots: with 8 pages a fifth of the loop's time, by py-spy). So
a pass first *takes* every page's samples in one go (each page's ``take``: a drain of its ring, no decoding), then
redraws the pages one per turn of the loop from what they took.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Callable, TypeVar

__all__ = ["Ticker", "OnePerTurn", "next_due"]

log = logging.getLogger("robofabric.console")

R = TypeVar("R")


class Ticker:
    """Calls every registered callback each ``period`` seconds, in the order they joined; a callback that raises
    is logged and counted, the others still run."""

    def __init__(self, period: float) -> None:
        self.period = period
        self._callbacks: dict[int, Callable[[], None]] = {}
        self._takes: dict[int, Callable[[], None]] = {}  # what a page takes at the start of a pass (its samples)
        self._next = 0
        self.failed = 0
        self.ticks = 0
        self.stretched = 0  # passes followed by a rest as long as they took (:func:`next_due`)
        self.last_pass_s = 0.0  # how long the last pass took, the loop's turns between its pages included

    def add(self, callback: Callable[[], None], take: Callable[[], None] | None = None) -> int:
        """Register ``callback``, and ``take`` (called for every page at the start of each pass, all in one go,
        before any page's ``callback``); the number :meth:`remove` takes."""
        self._next += 1
        self._callbacks[self._next] = callback
        if take is not None:
            self._takes[self._next] = take
        return self._next

    def remove(self, handle: int) -> None:
        self._callbacks.pop(handle, None)
        self._takes.pop(handle, None)

    def __len__(self) -> int:
        return len(self._callbacks)

    def tick(self) -> None:
        """One pass over every callback, in one go (tests call it alone)."""
        self.ticks += 1
        self._take_all()
        for handle in list(self._callbacks):
            self._call(handle)

    async def turn(self) -> None:
        """One pass: every page's take in one go, then every callback, the event loop turning between two of them
        (the clock's pass)."""
        self.ticks += 1
        self._take_all()
        for handle in list(self._callbacks):
            self._call(handle)
            await asyncio.sleep(0)

    def _take_all(self) -> None:
        for take in list(self._takes.values()):
            self._guarded(take, "take")

    def _call(self, handle: int) -> None:
        cb = self._callbacks.get(handle)  # None: removed since the pass began (its page left)
        if cb is not None:
            self._guarded(cb, "redraw")

    def _guarded(self, fn: Callable[[], None], what: str) -> None:
        try:
            fn()
        except Exception:
            self.failed += 1
            log.exception("console: a page's %s failed", what)

    async def run(self) -> None:
        """Tick every ``period`` seconds on the running loop, aligned to the loop's clock (a late tick does not
        push the next ones later), until cancelled; and never more than half the loop's time: a pass that took
        longer than half a period (a class on a starved box) is followed by as long a rest (:func:`next_due`)."""
        loop = asyncio.get_running_loop()
        due = loop.time()
        while True:
            due += self.period
            await asyncio.sleep(max(0.0, due - loop.time()))
            if loop.time() - due > self.period:  # far behind (a stalled loop): start again from now
                due = loop.time()
            start = loop.time()
            await self.turn()
            end = loop.time()
            self.last_pass_s = end - start
            nxt = next_due(due, self.period, start, end)
            if nxt > due + self.period:
                self.stretched += 1
            due = nxt - self.period  # the loop's next ``due += period`` lands on it


def next_due(due: float, period: float, start: float, end: float) -> float:
    """When the pass after one due at ``due`` (begun at ``start``, ended at ``end``) is due: a period later, or, when
    the pass took longer than the rest of that period, as long after its end as it took (the rest of the loop, the
    sockets' pings, keys and the pages' builds, get at least half of its time).

    A class's passes outlasted the period on a loaded 2-core box and ran back to back: the redraws took what CPU the
    console got, and each step of a socket's message (a ping's answer, a key, a login's answer) waited a page's
    redraw. The view is then redrawn less often (its lag grows) instead."""
    return max(due + period, end + (end - start))


class OnePerTurn:
    """Long calls of the event loop (a page's build: 0.1-5 s on a loaded box) one per turn of the loop.

    32 logins answered together are 32 builds ready in one turn of the loop, run back to back: the loop stood
    still for their sum (17-43 s), and every socket's ping went unanswered. A lock alone does not part them: a
    build that ends with nobody waiting lets the next one, ready in the same turn, in at once. Held over one turn
    after each call, the next call comes a turn later, after the loop answered what waited meanwhile."""

    def __init__(self) -> None:
        self._lock = asyncio.Lock()

    async def run(self, fn: Callable[[], R]) -> R:
        """``fn()`` on the loop, alone in its turn."""
        async with self._lock:
            out = fn()
            await asyncio.sleep(0)
            return out
