"""Looking the world up: the robots the sim peers describe on ``srv/world``, asked off Zenoh's callback threads.

Both compute services learn the world this way rather than from a local copy of the scene: kinematics the
arms and where their bases stand, navigation the mobile robots' LIDAR mounting and radius.
:func:`described_robots` is the one query; :class:`BackgroundLookup` runs a service's lookup one at a time
and at most once per interval, on a thread of its own or in the caller's, because a query must not run on
the Zenoh callback thread that found it was needed (a scan, a joint state, a sim's token).
"""

from __future__ import annotations

import math
import threading
from typing import TYPE_CHECKING, Callable

from fabric import keys
from fabric.interfaces import RobotInfo, WorldInfo
from fabric.rate import Clock, MonotonicClock

if TYPE_CHECKING:
    from fabric.session import Fabric

__all__ = ["BackgroundLookup", "described_robots"]


def described_robots(fabric: "Fabric", kind: str | None, *, timeout: float = 2.0) -> list[RobotInfo]:
    """The robots of ``kind`` (``arm``, ``mobile``; None: of every kind) every sim peer of the fabric's world describes.

    Raises :class:`~fabric.interfaces.ServiceError` when no sim answered (nobody serves ``srv/world``, or
    every answer was a refusal); an empty list means the sims answered and have no such robot.
    """
    replies = fabric.rpc.query(keys.srv(fabric.world, "world"), timeout=timeout, all_replies=True, expected=WorldInfo)
    return [r for rep in replies for r in rep.message.robots if kind is None or r.kind == kind]


class BackgroundLookup:
    """Runs ``lookup(timeout)`` one at a time, at most once per interval; after ``close()`` never again.

    ``start(interval)`` runs it on a thread of its own, ``claim(interval)`` then ``run(timeout)`` in the
    caller's; either way ``ended`` is the clock time the last run ended and ``wait`` joins a run under way.
    An exception from ``lookup`` goes to ``on_error`` (a session closing under it, say) and ends that run only.
    """

    def __init__(
        self,
        lookup: Callable[[float], object],
        *,
        name: str,
        on_error: Callable[[Exception], None],
        clock: Clock | None = None,
    ) -> None:
        self._lookup = lookup
        self._name = name
        self._on_error = on_error
        self._clock = clock or MonotonicClock()
        self._lock = threading.Lock()
        self._running = False
        self._closed = False
        self._started_at = -math.inf
        self._ended_at = -math.inf
        self._idle = threading.Event()
        self._idle.set()

    @property
    def running(self) -> bool:
        with self._lock:
            return self._running

    @property
    def ended(self) -> float:
        """The clock time the last run ended (``-inf`` before the first)."""
        with self._lock:
            return self._ended_at

    def until_allowed(self, interval: float) -> float:
        """Seconds until a claim with ``interval`` may succeed (0 or less: now, unless one is running)."""
        with self._lock:
            return self._started_at + interval - self._clock.now()

    def again_now(self) -> None:
        """Let the next claim through whatever the interval (what the lookup learns may have changed)."""
        with self._lock:
            self._started_at = -math.inf

    def claim(self, interval: float) -> bool:
        """Whether the caller should run the lookup now: none running, none started in the last ``interval``."""
        with self._lock:
            now = self._clock.now()
            if self._running or self._closed or now - self._started_at < interval:
                return False
            self._running = True
            self._started_at = now
            self._idle.clear()
            return True

    def run(self, timeout: float) -> None:
        """Run the lookup a successful :meth:`claim` granted, in this thread."""
        try:
            self._lookup(timeout)
        except Exception as exc:
            self._on_error(exc)
        finally:
            with self._lock:
                self._ended_at = self._clock.now()
                self._running = False
            self._idle.set()

    def start(self, interval: float, timeout: float = 2.0) -> bool:
        """Run the lookup on a thread of its own if :meth:`claim` allows; whether one was started."""
        if not self.claim(interval):
            return False
        threading.Thread(target=self.run, args=(timeout,), name=self._name, daemon=True).start()
        return True

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` for a run under way to end; whether none is running now."""
        return self._idle.wait(timeout)

    def close(self) -> None:
        """No run starts after this (one under way ends on its own)."""
        with self._lock:
            self._closed = True
