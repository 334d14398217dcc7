"""A liveliness watch whose last word on a token is the router's, not the order of two threads.

When a client's link drops and comes back (a process starved or paused past its 2 s lease: a loaded laptop, a
suite on four workers), zenoh tells its liveliness subscribers that every token it knew through the old link is
gone, and that the ones the new link shows are there. The two come from different tasks, and nothing orders them
for the subscriber: the going can come last. A watch that believed its last sample then held a live sim for gone,
for good: the demo's bob (issue 49's grouped runs) saw "world 'demo' gone" while the sim ran on, and his session's
fence refused every pose of that sim from then on, so his base reached its goal and he never saw it arrive.

So a watch checks a going with the router: :data:`RECHECK_S` after it, it asks which tokens are there (a liveliness
query); when the token is there and nothing was heard of it since the going, its callback hears it is back. A
token that truly went is answered by nobody, and nothing more happens. A change heard while a check is on its way
wins over the check's answer (:meth:`TokenWatch.recheck_answer`): the check may have been answered before it.

Only a going heard about a loss of this session's own link is checked (the race needs one), so a flood of 6,000
logins closing while the link holds asks nothing; and a check is one query for the watch's whole key expression,
whatever number of goings are due then. Sims' tokens are the exception (``link_lost_at=None``: the session's fence,
its world's presence, a viewer's, a recorder's): every going of one is checked. A CI run's demo had bob hear the
sim's token go while his link held (no loss of it logged, and the viewer and the sim heard nothing of it), the sim
serving on; his fence refused its every pose from then on, and he resent his path for 76 s to a base that had long
reached its goal. Sims are a world's few peers (a secure world lets no login but a sim's declare their tokens), so
checking each of their goings costs a query or four when one leaves. Checking every going of every watch, one query
per token, made the declaration flood's test 44 s -> 97 s and loaded the box beside it; one query per check time for
all of them, replies of thousands of tokens, did worse (116 s, and six tests beside it failed).
"""

from __future__ import annotations

import heapq
import itertools
import logging
import threading
import time
from collections.abc import Callable

import zenoh

__all__ = ["RECHECK_S", "TokenWatch"]

log = logging.getLogger("robofabric")

RECHECK_S: tuple[float, ...] = (0.5, 2.0, 5.0, 15.0)
"""Seconds after a going at which its token is asked for again: a client reconnects within about a second of its
link's loss (:data:`fabric.config.RECONNECT_RETRY`); the later checks cover a loaded box, where a link can take
seconds to come back (a check asked while it is down finds nothing, as for a token that went)."""
QUERY_TIMEOUT_S = 2.0
LINK_NEAR_S = 1.0
"""A going is checked when this session lost a link no longer than this before it was heard, or any time after (the
link's close and the goings it brings are told on different threads, in either order). A going heard while the
link held, as each of a flood's 6,000 closing logins, is the router's word: nothing is asked."""
MIN_INTERVAL_S = 0.25
"""The least time between two of a watch's checks: a flood's goings, due one after another, share a query."""
"""How long a check's liveliness query may take (the router answers from its table)."""
MAX_PENDING = 4096
"""Goings a watch keeps waiting for their checks: a flood of made-up tokens coming and going costs no more."""


class TokenWatch:
    """``callback(key, alive)`` on every liveliness token under ``key_expr`` that appears or goes (existing ones
    first, with ``history``), a going checked with the router as the module says. ``undeclare()`` ends it
    (idempotent). Calls to ``callback`` are serialized: one at a time, in the order decided."""

    def __init__(
        self,
        session: zenoh.Session,
        key_expr: str,
        callback: Callable[[str, bool], None],
        *,
        history: bool = True,
        recheck_s: tuple[float, ...] | None = None,
        link_lost_at: Callable[[], float] | None = None,
    ) -> None:
        """``link_lost_at()``: when this session last lost a link (monotonic s); a going is checked only when one was
        lost about then (None: every going is checked)."""
        self._link_lost_at = link_lost_at
        self._session = session
        self._callback = callback
        self._recheck_s = RECHECK_S if recheck_s is None else recheck_s  # read now: a test shortens it
        self._lock = threading.RLock()
        self._heard: dict[str, int] = {}  # a gone token's key -> changes heard of it (only while checks are due)
        self._due: dict[str, int] = {}  # that key -> checks still due
        self._count = itertools.count(1)
        self._checks: list[tuple[float, str, int, float]] = []  # (when, key, the change it asks about, gone at): a heap
        self._called_at: float | None = None  # when the rechecker calls check_due next (None: not scheduled)
        self._key_expr = key_expr
        self._closed = False
        self.rechecks = 0
        """Checks answered (or failed): a test waits on it."""
        self.restored = 0
        """Tokens a check found there after their going was heard."""
        self.queries = 0
        """Liveliness queries the checks made."""
        self._sub = session.liveliness().declare_subscriber(key_expr, self._on_sample, history=history)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self.heard(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

    def heard(self, key: str, alive: bool) -> None:
        """A token's change as the subscription delivers it: told to the callback; a going is checked later."""
        with self._lock:
            if self._closed:
                return
            if key in self._heard:
                self._heard[key] = next(self._count)
            elif not alive and len(self._checks) + len(self._recheck_s) <= MAX_PENDING:
                self._heard[key] = next(self._count)
            if not alive and key in self._heard and self._recheck_s:
                mark, now = self._heard[key], time.monotonic()
                self._due[key] = self._due.get(key, 0) + len(self._recheck_s)
                for delay in self._recheck_s:
                    heapq.heappush(self._checks, (now + delay, key, mark, now))
                first = now + min(self._recheck_s)
                if self._called_at is None or first < self._called_at:
                    self._called_at = first
                    _RECHECKER.schedule(first, self)
            self._tell(key, alive)

    def called_at(self) -> float | None:
        """When the rechecker is to call :meth:`check_due` next (None: never)."""
        with self._lock:
            return self._called_at

    def check_due(self) -> float | None:
        """Ask the router once for every check due now; returns when to be called next (None: no check left). At
        most one query every :data:`MIN_INTERVAL_S`, whatever number of goings come due."""
        with self._lock:
            now = time.monotonic()
            due: list[tuple[str, int, float]] = []
            while self._checks and self._checks[0][0] <= now:
                _, key, mark, gone_at = heapq.heappop(self._checks)
                due.append((key, mark, gone_at))
            if self._closed:
                self._checks.clear()
        lost = self._link_lost_at() if self._link_lost_at is not None else float("inf")
        asked = [(k, m) for k, m, gone_at in due if lost >= gone_at - LINK_NEAR_S]  # goings about a link's loss
        for key, mark, gone_at in due:
            if lost < gone_at - LINK_NEAR_S:
                self.recheck_answer(key, mark, None)  # this session's link held: the going is the router's word
        if asked and not self._closed:
            present = self.ask_all()
            for key, mark in asked:
                self.recheck_answer(key, mark, None if present is None else key in present)
        with self._lock:
            nxt = (
                max(self._checks[0][0], time.monotonic() + MIN_INTERVAL_S)
                if self._checks and not self._closed
                else None
            )
            self._called_at = nxt
            return nxt

    def recheck_answer(self, key: str, mark: int, present: bool | None) -> None:
        """A check of ``key`` asked after the change numbered ``mark`` was heard: ``present`` whether the router
        has the token (None: the query failed). A token still there, with nothing heard of it since, is back."""
        with self._lock:
            self.rechecks += 1
            last = self._heard.get(key)
            due = self._due.get(key, 0) - 1
            if due > 0:
                self._due[key] = due
            else:  # its last check: the key is forgotten
                self._due.pop(key, None)
                self._heard.pop(key, None)
            if self._closed or not present or last != mark:
                return
            if due > 0:
                self._heard[key] = next(self._count)  # the checks still due were asked about the going: moot now
            self.restored += 1
            log.info("token %s is there after its going was heard: the link came back in another order", key)
            self._tell(key, True)

    def _tell(self, key: str, alive: bool) -> None:
        try:
            self._callback(key, alive)
        except Exception:  # a callback's fault must not stop the watch
            log.exception("liveliness callback on %s failed", key)

    def ask_all(self) -> set[str] | None:
        """The keys of the tokens the router has under this watch's key expression now (None: the query failed, or
        the session is closed)."""
        self.queries += 1
        try:
            replies = self._session.liveliness().get(self._key_expr, timeout=QUERY_TIMEOUT_S)
            return {str(r.ok.key_expr) for r in replies if r.ok is not None}
        except Exception:
            return None

    def undeclare(self) -> None:
        """Stop: nothing more reaches the callback. Takes no lock, so a closer holding a lock that the callback
        takes cannot wait on a callback that waits on it."""
        if self._closed:
            return
        self._closed = True
        try:
            self._sub.undeclare()
        except Exception:  # gone with a closing session
            pass


class _Rechecker:
    """One thread for every watch of the process, started when a check is first due: checks are rare (a link
    that dropped), so a class's pages, each with its watches, cost no thread until then."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, TokenWatch]] = []
        self._cond = threading.Condition()
        self._order = itertools.count()
        self._thread: threading.Thread | None = None

    def schedule(self, when: float, watch: TokenWatch) -> None:
        """Have ``watch`` check what is due at ``when``; an entry for a time the watch no longer expects is passed
        over (:meth:`TokenWatch.called_at`), so each watch has one chain of calls."""
        with self._cond:
            heapq.heappush(self._heap, (when, next(self._order), watch))
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._run, name="token-recheck", daemon=True)
                self._thread.start()
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._heap or self._heap[0][0] > time.monotonic():
                    if not self._heap:
                        self._cond.wait(5.0)
                        if not self._heap:
                            self._thread = None  # idle: the next check starts another
                            return
                    else:
                        self._cond.wait(max(0.0, self._heap[0][0] - time.monotonic()))
                when, _, watch = heapq.heappop(self._heap)
            if watch.called_at() != when:
                continue  # a watch called sooner since, or no longer: one chain of calls per watch
            later = watch.check_due()
            if later is not None:
                self.schedule(later, watch)


_RECHECKER = _Rechecker()
