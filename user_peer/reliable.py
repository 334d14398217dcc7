"""Send until it took effect: how a stop or a reset is made reliable over drop-on-congestion commands.

Robot commands travel with zenoh's congestion control DROP (docs/architecture.md says why), so
one ``cmd/stop`` can be lost in a flood. A stop and a reset are idempotent, so the sender sends
again every ``interval`` until the robot's own stream shows the effect (``done()``), or gives
up after ``timeout``. The robot's state is the acknowledgement: no new message type, and it
works against any sim peer.

A user's loop (``Robot.stop()``, ``reset()``): no sim, compute peer or authority re-sends anything, so it
lives with the user peer, not on the ground floor.

Pure loop: the clock and the sleep are passed in (tests use a fake clock).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

from fabric.rate import Clock, MonotonicClock

__all__ = ["Resent", "resend_until"]


@dataclass(frozen=True, slots=True)
class Resent:
    """How it went: whether the effect was seen, after how many sends and how many seconds."""

    done: bool
    sends: int
    seconds: float

    def __bool__(self) -> bool:
        return self.done


def resend_until(
    send: Callable[[], None],
    done: Callable[[], bool],
    *,
    interval: float = 0.1,
    timeout: float = 3.0,
    poll: float = 0.01,
    clock: Clock | None = None,
    sleep: Callable[[float], None] = time.sleep,
) -> Resent:
    """``send()``, then again every ``interval`` until ``done()`` is true or ``timeout`` passed."""
    if interval <= 0 or timeout < 0 or poll <= 0:
        raise ValueError("interval and poll must be > 0, timeout >= 0")
    clock = clock or MonotonicClock()
    t0 = clock.now()
    send()
    sends = 1
    while True:
        if done():
            return Resent(True, sends, clock.now() - t0)
        now = clock.now()
        if now - t0 >= timeout - 1e-9:
            return Resent(False, sends, now - t0)
        if now - t0 >= sends * interval - 1e-9:  # on a grid: t0, t0 + interval, ...
            send()
            sends += 1
        sleep(poll)
