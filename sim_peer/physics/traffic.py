"""Who gives way when bases wait for each other: the one decision that ends a deadlock between way guards.

Each base's :class:`~sim_peer.physics.way_guard.WayGuard` stops before what is in its way and waits for it to clear. Two
bases that meet in a gap (or three in a ring) may each wait for the other: neither way ever clears, and after
:data:`~sim_peer.physics.way_guard.BLOCKED_AFTER` both dropped their paths at once, planned again at once, and met again
(the class-nav bench's bases did, between the shelves). So the bases of one sim share a :class:`Traffic` board:
each guard posts where its base stands and, while it waits, a :class:`Waiter` naming the base in its way. When the
waiters form a cycle (A waits for B, B for A; or A for B, B for C, C for A) that has lasted
:data:`GIVE_WAY_AFTER` seconds of sim time, exactly one of them gives way (:func:`gives_way`, pure, time passed
in): the one that began waiting last, the greatest id on a tie. It drops its path and reports ``blocked`` at once,
naming the base it gave way to, so that its user plans again, with the other robots as obstacles (plans do:
docs/navigation.md); the others keep their paths and go on once it has moved off.

The board also lets a guard see the other bases of its sim all around, not only in its LIDAR's field (the Reeman's
looks 135 degrees ahead: a base coming from the side was seen too late, and bumped): a fleet's traffic system
knows where its robots are. Robots other sims simulate are seen by the LIDAR only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

__all__ = ["GIVE_WAY_AFTER", "Spot", "Traffic", "Waiter", "crossing", "cycle_of", "gives_way", "yields"]

GIVE_WAY_AFTER = 2.0
"""Seconds of sim time a cycle of waiting bases lasts before one of them gives way (well under ``BLOCKED_AFTER``:
a base that waits for a base passing by is not in a cycle, and waits as before)."""


@dataclass(frozen=True, slots=True)
class Waiter:
    """A base waiting for its way to clear: since when (sim time), and the base in its way (None: not a base)."""

    since: float
    blocker: str | None


@dataclass(frozen=True, slots=True)
class Spot:
    """Where a base stands (x, y, metres), its radius, and its way: the points of the path it follows, ahead of it
    (() when it follows none)."""

    x: float
    y: float
    radius: float
    way: tuple[tuple[float, float], ...] = ()


def crossing(mine: np.ndarray, theirs: np.ndarray, reach: float) -> tuple[float, float] | None:
    """How far two bases can go along their ways ahead ((n, 2) and (m, 2), each from where its base stands) before
    either comes within ``reach`` of any point of the other's: (my arc length to my last point clear of their way,
    theirs to their last point clear of mine); None when the ways never come that near.

    Symmetric (``crossing(b, a)`` is ``crossing(a, b)`` swapped), so both bases' guards weigh the same two numbers.
    Where both stand is left out (their spots are :func:`~sim_peer.physics.way_guard.base_gap`'s): this is about two
    bases heading for the same place, each unseen by the other's check of where it stands until too late to brake
    (two crossing in a gap stopped 0.10 m short, centres 0.59 m apart, on the bumper)."""
    if mine.shape[0] < 2 or theirs.shape[0] < 2:
        return None
    near = ((mine[:, None, :] - theirs[None, :, :]) ** 2).sum(axis=2) < reach * reach
    near[0, 0] = False
    rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    if rows.size == 0:
        return None
    return _arc(mine, int(rows[0]) - 1), _arc(theirs, int(cols[0]) - 1)


def _arc(points: np.ndarray, k: int) -> float:
    """Arc length along ``points`` to point ``k`` (0 for k <= 0)."""
    return float(np.hypot(*np.diff(points[: k + 1], axis=0).T).sum()) if k > 0 else 0.0


def yields(me: str, mine: float, them: str, theirs: float, yielding: Mapping[str, str] | None = None) -> bool:
    """Whether base ``me``, ``mine`` metres from where its way meets base ``them``'s, lets it through first: the
    base further from the meeting goes second (the other gets there first), the greater id on a tie. One of two
    bases yields, the same one whichever asks.

    ``yielding`` (the board's: who yields to whom now) keeps a choice made until their ways part: two bases as far
    from the meeting (mirrored starts, one map) swapped who yielded from one look to the next, each braking and going
    by turns, and met on the bumper."""
    if yielding is not None:
        if yielding.get(them) == me:
            return False
        if yielding.get(me) == them:
            return True
    return mine > theirs or (mine == theirs and me > them)


def cycle_of(waiters: Mapping[str, Waiter], robot: str) -> tuple[str, ...]:
    """The bases of the cycle of waits ``robot`` is in, from ``robot`` on; () when its waits lead elsewhere (to a
    base that moves or stands idle, to a wall, to a cycle it is not part of)."""
    chain: list[str] = []
    at: str | None = robot
    while at is not None and at in waiters and at not in chain:
        chain.append(at)
        at = waiters[at].blocker
    return tuple(chain) if at == robot else ()


def gives_way(waiters: Mapping[str, Waiter], robot: str, now: float, *, after: float = GIVE_WAY_AFTER) -> str | None:
    """The base ``robot`` should give way to now (its blocker), or None.

    It gives way when it is in a cycle of waiting bases, every one of them has waited at least ``after`` s, and it
    is the one of the cycle that began waiting last (on a tie, the greatest id): one base per cycle, the same one
    whichever guard asks, since every guard reads the same board."""
    cycle = cycle_of(waiters, robot)
    if not cycle or now - max(waiters[r].since for r in cycle) < after:
        return None
    last = max(cycle, key=lambda r: (waiters[r].since, r))
    return waiters[robot].blocker if last == robot else None


class Traffic:
    """The board the way guards of one sim share: every base's spot, and the waiters. Guards run on the sim's
    stepping thread, one after another, so it needs no lock."""

    def __init__(self) -> None:
        self.spots: dict[str, Spot] = {}
        self.waiters: dict[str, Waiter] = {}
        self.yielding: dict[str, str] = {}  # base -> the base it lets through first, while their ways meet

    def stand(self, robot: str, spot: Spot) -> None:
        """``robot`` stands at ``spot`` now."""
        self.spots[robot] = spot

    def wait(self, robot: str, waiter: Waiter | None) -> None:
        """``robot`` waits (``waiter``) or no longer does (None)."""
        if waiter is None:
            self.waiters.pop(robot, None)
        else:
            self.waiters[robot] = waiter

    def others(self, robot: str) -> dict[str, Spot]:
        """Every base's spot but ``robot``'s."""
        return {r: s for r, s in self.spots.items() if r != robot}
