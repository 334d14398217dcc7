"""Whether the authority could hear users' tokens go, and whom it must confirm once it hears again.

A user's liveliness token going means she left, unless the authority itself was deaf: its link down (the
router dropped it, or went), or its process paused or starved (no tick for over half a lease, or resumed
less than a lease and a second ago). Then every token goes at once and none of those users left. Users whose
token went while it was deaf, and those a standby inherited from the authority it replaced, are kept
unconfirmed: once the link is up, those whose token has not come back within a lease and a second left
while nobody could tell. The clock for that starts when the link is back, never while it is down.

Pure bookkeeping: times are values passed in (the authority's clock), the link's state too.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable

CONFIRM_SLACK_S = 1.0  # on top of a lease: the liveliness history a token needs to show up again


class Hearing:
    """The authority's deafness and its unconfirmed users; ``now`` is the authority's clock."""

    def __init__(self, lease_s: float, now: float, *, unconfirmed: Iterable[str] = ()) -> None:
        self.lease_s = lease_s
        self._lock = threading.Lock()
        self._last_tick_at: float | None = None
        self._resumed_at: float | None = None
        self._unconfirmed: set[str] = set(unconfirmed)
        self._confirm_by: float | None = now + lease_s + CONFIRM_SLACK_S

    def tick(self, now: float) -> float:
        """The authority ticked at ``now``: the seconds it did not run before, when over half a lease (it was
        paused or starved, and tokens that go in the next lease may be its own trouble), else 0."""
        with self._lock:
            last, self._last_tick_at = self._last_tick_at, now
            if last is not None and now - last > self.lease_s / 2:
                self._resumed_at = now
                return now - last
            return 0.0

    def deaf(self, now: float, connected: bool) -> bool:
        """Whether a token going at ``now`` may be the authority's own trouble."""
        with self._lock:
            last, resumed = self._last_tick_at, self._resumed_at
        return (
            not connected
            or (last is not None and now - last > self.lease_s / 2)
            or (resumed is not None and now < resumed + self.lease_s + CONFIRM_SLACK_S)
        )

    def suspect(self, user: str) -> None:
        """``user``'s token went while the authority was deaf: she must show up again once it hears."""
        with self._lock:
            self._unconfirmed.add(user)
            self._confirm_by = None

    def confirm(self, user: str) -> None:
        """``user``'s token is here (or went while the authority heard): nothing to confirm."""
        with self._lock:
            self._unconfirmed.discard(user)

    @property
    def pending(self) -> bool:
        """Whether some user is still to be confirmed."""
        with self._lock:
            return bool(self._unconfirmed)

    def due(self, now: float, connected: bool) -> list[str]:
        """The unconfirmed users who left: those whose token did not come back within a lease and a second of the
        link being up; they are forgotten here. Empty while the link is down or the time has not come."""
        with self._lock:
            if not connected:
                self._confirm_by = None
                return []
            if self._confirm_by is None:
                self._confirm_by = now + self.lease_s + CONFIRM_SLACK_S
                return []
            if now <= self._confirm_by:
                return []
            gone = sorted(self._unconfirmed)
            self._unconfirmed.clear()
            return gone


__all__ = ["CONFIRM_SLACK_S", "Hearing"]
