"""``srv/state`` answered apart: off zenoh's callback thread, a bounded few a second.

A whole-world state (every robot, every record, the sequence numbers) costs milliseconds to capture and
encode; answered in zenoh's callback thread, a flood of ``srv/state`` queries (every login may ask it)
held up everything behind it on the sim's link: another student's ``srv/world`` went unanswered for 16 s
(issue 42). So, as :class:`StateAnswers` does it:

- the answers are worked out on a :class:`fabric.lanes.Lane` of their own: ``srv/world``, the ownership
  renewals and the commands that come on the same link never wait behind them;
- at most :data:`BUDGET` answers go out a second (a burst of as many at once) and :data:`WAITING` wait
  there; past that an ask is refused at once as ``rate_limited``, counted under ``rate_limited`` in the
  session's counters. The key names no login (``srv/state`` carries none), so the budget is the sim's,
  not each login's: under a flood a standby's polls (20 a second) are refused too, and it follows the
  streams meanwhile.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable

from fabric.budget import RATE_LIMITED, Rate, take
from fabric.interfaces import ServiceError
from fabric.lanes import Lane

__all__ = ["StateAnswers", "WAITING", "BUDGET"]

BUDGET = Rate(50.0, 50.0)
"""``srv/state`` answers a sim gives a second (all askers together: the key names none)."""

WAITING = 8
"""``srv/state`` answers that may wait for the lane at once."""


class StateAnswers:
    """``route`` is the ``srv/state`` queryable's ``defer``: its handler then runs on this lane."""

    def __init__(self, counters: Any, *, clock: Callable[[], float] = time.monotonic, budget: Rate = BUDGET) -> None:
        self._counters = counters
        self._budget = budget
        self._bucket = None
        self._clock = clock
        self.lane = Lane("srv-state", per_asker=WAITING, total=WAITING)
        self._lock = threading.Lock()

    def route(self, key: str, request: Any) -> Callable[[Callable[[], None]], bool] | None:
        """An ask for the world's state within the budget goes to the lane; past it, or when the lane is full, it
        is refused as ``rate_limited`` (counted here). An ask with a payload (a sim asking which shard another
        serves, a move step refused) costs no capture: answered at once, as ``srv/world`` is."""
        if request is not None:
            return None
        with self._lock:
            self._bucket, ok = take(self._bucket, self._budget, self._clock())
        if not ok:
            self._counters["rate_limited"] += 1
            raise ServiceError(f"{RATE_LIMITED}: this sim answers srv/state at most {self._budget}; ask again later")

        def submit(job: Callable[[], None]) -> bool:
            ok = self.lane.submit("", job)
            if not ok:
                self._counters["rate_limited"] += 1
            return ok

        return submit

    def close(self) -> None:
        self.lane.close()
