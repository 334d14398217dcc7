"""A user's lease renewals: what she holds, renewed every ``renew_s`` until the authority says otherwise.

The authority expires a lease that is not renewed (:mod:`ownership.state`); :class:`Renewal` keeps the
leases of one user alive. What she holds is what the authority granted her in a reply (``hold``), or handed
to her in a trusted record (a queue's turn, found in ``records()``); only the authority's answer to a
renewal ends it, never a published record on its own. Each round renews everything at once on a small
pool, one renewal per object in flight, so a slow answer delays neither the other objects nor the next
round. A renewal unanswered for :data:`STUCK_ROUNDS` rounds is not waited for: the object is renewed again
beside it (at most :data:`MAX_IN_FLIGHT` at once). Before, one query whose answer never came held that
object's renewals for the query's whole limit (10 s), five leases of 2 s, with its owner there and renewing her
other robots.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor

from fabric.interfaces import OwnershipRecord, OwnReply, ServiceError

log = logging.getLogger("robofabric.ownership")

STUCK_ROUNDS = 2
"""A renewal unanswered for this many rounds is not waited for: the object is renewed again beside it."""

MAX_IN_FLIGHT = 3
"""Renewals of one object in flight at once, at most (each holds a thread of the pool until its limit)."""

LATE_ROUND_S = 1.0
"""A round that began this much after it was due is said (a warning): the process did not run (paused or starved),
and a lease runs out a lease after the last renewal that reached the authority, whoever is at fault."""


class Renewal:
    """Renews ``user``'s leases: ``ask(obj)`` sends one renewal and returns the authority's reply,
    ``records()`` gives the trusted records, ``closed()`` says the session is going (a failure then is
    no news)."""

    def __init__(
        self,
        user: str,
        ask: Callable[[str], OwnReply],
        records: Callable[[], Mapping[str, OwnershipRecord]],
        *,
        renew_s: float,
        closed: Callable[[], bool] = lambda: False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.user = user
        self.renew_s = renew_s
        self._ask = ask
        self._records = records
        self._closed = closed
        self._lock = threading.Lock()
        self._held: set[str] = set()  # granted to us; renewed until the authority says otherwise
        self._renewing: dict[str, list[float]] = {}  # object -> when each renewal in flight was sent
        self._missed: set[str] = set()  # objects whose last renewal went unanswered (said once, until answered)
        self._clock = clock
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.latest_late_s = 0.0
        """How late the latest round said late (:data:`LATE_ROUND_S`) began, in seconds (0: none so far)."""

    def hold(self, obj: str) -> None:
        """The authority granted ``obj``: renew it from the next round on."""
        with self._lock:
            self._held.add(obj)

    def drop(self, obj: str) -> None:
        """Stop renewing ``obj`` (a release on its way)."""
        with self._lock:
            self._held.discard(obj)

    def held(self) -> list[str]:
        """What this user holds: granted in a reply, or handed over in a trusted record (exclusive ones)."""
        records = self._records()
        with self._lock:
            for obj, rec in records.items():
                if rec.owner == self.user and rec.policy == "exclusive":
                    self._held.add(obj)
            return sorted(self._held)

    def start(self) -> None:
        """Start the rounds on a daemon thread (once; a second call does nothing)."""
        with self._lock:
            if self._thread is None and not self._stop.is_set():
                self._thread = threading.Thread(target=self._loop, name=f"own-renew-{self.user}", daemon=True)
                self._thread.start()

    def _loop(self) -> None:
        """Every ``renew_s`` from the start of the last round, renew everything held, all at once, so a lease
        sees a renewal every ``renew_s`` however long each round trip takes."""
        with ThreadPoolExecutor(max_workers=8, thread_name_prefix=f"own-renew-{self.user}") as pool:
            next_at = time.monotonic() + self.renew_s
            while not self._stop.wait(max(0.0, next_at - time.monotonic())):
                late = time.monotonic() - next_at
                if late >= LATE_ROUND_S:
                    # said, so that a lease lost to a stall of the owner's own process is told apart from one lost on
                    # the way (a class of eight lost a lease now and then at load, and nothing said which)
                    self.latest_late_s = late
                    log.warning(
                        "renewals of %s: a round began %.1f s late (this process did not run: paused or starved)",
                        self.user,
                        late,
                    )
                next_at = max(next_at + self.renew_s, time.monotonic())
                for obj in self.held():
                    if not self._take_turn(obj, self._clock()):
                        continue
                    try:
                        pool.submit(self._renew, obj)
                    except RuntimeError:  # the interpreter is exiting under a session left open: no more rounds
                        return

    def _take_turn(self, obj: str, now: float) -> bool:
        """Whether ``obj`` is renewed this round (then its renewal counts as sent at ``now``): when none is in
        flight, or the last one sent has waited :data:`STUCK_ROUNDS` rounds and fewer than :data:`MAX_IN_FLIGHT`
        are out."""
        with self._lock:
            sent = self._renewing.setdefault(obj, [])
            if sent and (now - sent[-1] < STUCK_ROUNDS * self.renew_s or len(sent) >= MAX_IN_FLIGHT):
                return False  # still waiting for the last answer
            sent.append(now)
            return True

    def in_flight(self, obj: str) -> int:
        """Renewals of ``obj`` sent and not answered yet."""
        with self._lock:
            return len(self._renewing.get(obj, ()))

    def _renew(self, obj: str) -> None:
        try:
            self._renew_once(obj)
        finally:
            with self._lock:
                sent = self._renewing.get(obj)
                if sent:
                    sent.pop(0)
                if not sent:
                    self._renewing.pop(obj, None)

    def _renew_once(self, obj: str) -> None:
        t0 = time.monotonic()
        try:
            reply = self._ask(obj)
        except ServiceError as exc:  # no answer this time: the next round asks again
            if not (self._stop.is_set() or self._closed()) and self._first_miss(obj):
                # said, once until one is answered: her lease runs out after a few of these (a class of eight once
                # lost a base with its owner renewing her arm beside it, and nothing told why)
                log.warning(
                    "renewal of %s by %s: not renewed after %.1f s (%s); asking again every round",
                    obj,
                    self.user,
                    time.monotonic() - t0,
                    exc,
                )
            return
        except Exception:  # the session is closing
            if not (self._stop.is_set() or self._closed()):
                log.debug("renewal of %s failed", obj, exc_info=True)
            return
        with self._lock:
            missed = obj in self._missed
            self._missed.discard(obj)
        if missed:
            log.warning("renewal of %s by %s: answered again (%s)", obj, self.user, reply.outcome)
        if reply.outcome != "renewed" and reply.record.owner != self.user:
            self.drop(obj)

    def _first_miss(self, obj: str) -> bool:
        """Whether this unanswered renewal of ``obj`` is the first since one was answered."""
        with self._lock:
            first = obj not in self._missed
            self._missed.add(obj)
            return first

    def close(self) -> None:
        """No more rounds; waits (up to 2 s) for the one under way, unless called from it."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)


__all__ = ["LATE_ROUND_S", "MAX_IN_FLIGHT", "Renewal", "STUCK_ROUNDS"]
