"""The user peer's cache: the latest message per key, which every blocking call of the API waits on.

A :class:`~user_peer.world.World` feeds it from Zenoh's threads; robot handles read it and wait on its
condition. Freshness and order are local (arrival numbers, this machine's clock), never the sender's.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from typing import Any, Callable

from fabric.interfaces import WorldInfo

__all__ = ["Latest"]


class Latest:
    """The latest message per key, with a condition to wait for a newer one.

    Freshness is judged on this machine only: every message gets a local arrival number (``mark()``
    reads the current one) and a local receive time from ``clock`` (monotonic ns). A header's
    ``wall_ns`` comes from another machine's clock and is never compared with ours.

    Bounded by what the world has, not by what clients make up: once ``world_info()``
    gives the world description, a robot key (``robot/{id}/...``) or record (``own/{id}``) is kept only
    for a robot or object of that description; anything else (before the description, maps, events)
    shares ``max_other`` places, the least recently updated forgotten first, so made-up keys
    (``robot/fakeN/scan``, 4 MiB each) cannot grow a user's memory without bound.
    """

    def __init__(
        self,
        clock: Callable[[], int] = time.monotonic_ns,
        *,
        world_info: Callable[[], WorldInfo | None] | None = None,
        max_other: int = 64,
    ) -> None:
        self._values: dict[str, tuple[Any, int, int]] = {}
        self._other: OrderedDict[str, None] = OrderedDict()  # keys outside the description, oldest update first
        self._cond = threading.Condition()
        self._gen = 0
        self._clock = clock
        self._world_info = world_info
        self._max_other = max_other
        self._ids: tuple[Any, frozenset[str]] = (None, frozenset())  # (description, its robot and object ids)
        self.dropped = 0  # messages on keys of robots the world does not have

    def _known(self, key: str) -> bool | None:
        """True: a key of the world's robots or objects; False: of one it does not have; None: no description
        yet, or a key of another kind."""
        info = self._world_info() if self._world_info is not None else None
        if info is None:
            return None
        if self._ids[0] is not info:
            self._ids = (info, frozenset(r.id for r in info.robots) | frozenset(o.id for o in info.objects))
        parts = key.split("/", 4)  # rf/{world}/{category}/{subject}/...: the object pose key here ends in a wildcard
        if len(parts) >= 4 and parts[2] in ("robot", "own", "object"):
            return parts[3] in self._ids[1]
        return None

    def __len__(self) -> int:
        """How many keys are kept (bounded: a client cannot grow it with keys the world does not have)."""
        with self._cond:
            return len(self._values)

    def put(self, key: str, msg: Any) -> None:
        known = self._known(key)
        if known is False:
            self.dropped += 1
            return
        with self._cond:
            self._gen += 1
            if known:
                self._other.pop(key, None)
            elif key in self._other:
                self._other.move_to_end(key)
            else:
                self._other[key] = None
                while len(self._other) > self._max_other:
                    self._values.pop(self._other.popitem(last=False)[0], None)
            self._values[key] = (msg, self._gen, self._clock())
            self._cond.notify_all()

    def get(self, key: str) -> Any:
        with self._cond:
            v = self._values.get(key)
            return v[0] if v else None

    def mark(self) -> int:
        """The arrival number of the newest message so far: ``get_after(key, mark)`` ignores older ones."""
        with self._cond:
            return self._gen

    def get_after(self, key: str, mark: int) -> Any:
        """The latest message on ``key`` if it arrived after ``mark``, else None."""
        with self._cond:
            v = self._values.get(key)
            return v[0] if v and v[1] > mark else None

    def age(self, key: str) -> float | None:
        """Seconds since the latest message on ``key`` arrived here (None: nothing yet)."""
        with self._cond:
            v = self._values.get(key)
        return None if v is None else max(0.0, (self._clock() - v[2]) * 1e-9)

    def wait_for(self, predicate: Callable[[], Any], timeout: float) -> Any:
        """Re-evaluate ``predicate`` on every new message until it is truthy or ``timeout`` passes."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                value = predicate()
                if value:
                    return value
                left = deadline - time.monotonic()
                if left <= 0:
                    return value
                self._cond.wait(min(left, 0.1))
