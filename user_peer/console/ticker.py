"""One clock for every page's redraw, so that what pages share is computed once per tick.

Each page used to redraw on a timer of its own, started when it logged in: twenty timers at twenty phases,
each reading the world a little later than the one before, so no two pages held the same newest pose and
nothing could be shared between them. One ticker calls every page in turn, one after another in one pass of
the event loop: the pages read the same samples, and :class:`~user_peer.console.feed.Decoded` and the view's
drawing cache (:func:`user_peer.console.topview.robot_svg`) do the work once per tick for all of them.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Callable

__all__ = ["Ticker"]

log = logging.getLogger("robofabric.console")


class Ticker:
    """Calls every registered callback each ``period`` seconds, in the order they joined; a callback that raises
    is logged and counted, the others still run."""

    def __init__(self, period: float) -> None:
        self.period = period
        self._callbacks: dict[int, Callable[[], None]] = {}
        self._next = 0
        self.failed = 0
        self.ticks = 0

    def add(self, callback: Callable[[], None]) -> int:
        """Register ``callback``; the number :meth:`remove` takes."""
        self._next += 1
        self._callbacks[self._next] = callback
        return self._next

    def remove(self, handle: int) -> None:
        self._callbacks.pop(handle, None)

    def __len__(self) -> int:
        return len(self._callbacks)

    def tick(self) -> None:
        """One pass over every callback (the loop's body; called alone by tests)."""
        self.ticks += 1
        for cb in list(self._callbacks.values()):
            try:
                cb()
            except Exception:
                self.failed += 1
                log.exception("console: a page's redraw failed")

    async def run(self) -> None:
        """Tick every ``period`` seconds on the running loop, aligned to the loop's clock (a late tick does not
        push the next ones later), until cancelled."""
        loop = asyncio.get_running_loop()
        due = loop.time()
        while True:
            due += self.period
            await asyncio.sleep(max(0.0, due - loop.time()))
            if loop.time() - due > self.period:  # far behind (a stalled loop): start again from now
                due = loop.time()
            self.tick()
