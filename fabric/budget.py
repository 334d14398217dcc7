"""Per-login budgets: a token bucket for each login, so that one login's flood spends her own budget only.

A peer that serves everyone (the ownership authority, a sim's services) answers each login from her own
:class:`Bucket`: ``burst`` asks at once, then ``per_s`` a second. What goes past it is refused as
``rate_limited`` (:data:`RATE_LIMITED`), cheaply and at once, and counted; other logins' buckets are
untouched, so their answers and leases never wait behind her. :func:`take` is pure (time passed in) and
property-tested; :class:`Budgets` keeps one bucket per login behind a lock, bounded in how many it keeps.
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from dataclasses import dataclass

__all__ = ["RATE_LIMITED", "Rate", "Bucket", "take", "Budgets"]

RATE_LIMITED = "rate_limited"
"""The first word of every refusal for a spent budget: what a client, a log or a test looks for."""


@dataclass(frozen=True, slots=True)
class Rate:
    """``per_s`` asks a second on average, ``burst`` at once after a quiet spell."""

    per_s: float
    burst: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.per_s) and self.per_s > 0 and math.isfinite(self.burst) and self.burst >= 1):
            raise ValueError(
                f"a budget needs a positive rate and a burst of at least 1, got {self.per_s}/s, burst {self.burst}"
            )

    @classmethod
    def parse(cls, text: str) -> "Rate":
        """``"5/10"``: 5 a second, 10 at once; ``"5"``: 5 a second, 10 at once (twice the rate, at least 1)."""
        head, _, tail = text.strip().partition("/")
        try:
            per_s = float(head)
            burst = float(tail) if tail else max(1.0, 2 * per_s)
            return cls(per_s, burst)
        except ValueError:
            raise ValueError(
                f"a budget is RATE or RATE/BURST (asks a second / at once, e.g. 5/10), got {text!r}"
            ) from None

    def __str__(self) -> str:
        return f"{self.per_s:g}/s (burst {self.burst:g})"


@dataclass(frozen=True, slots=True)
class Bucket:
    """What is left of one login's budget (``tokens``) as of ``at`` (seconds, the server's monotonic clock)."""

    tokens: float
    at: float


def take(bucket: Bucket | None, rate: Rate, now: float, cost: float = 1.0) -> tuple[Bucket, bool]:
    """Spend ``cost`` from ``bucket`` at ``now``: the bucket after, and whether it was there to spend.

    A missing bucket is a full one. Tokens come back at ``rate.per_s`` up to ``rate.burst``; a ``now``
    before the bucket's time (a clock read on another thread, a little late) counts as no time passed."""
    if bucket is None:
        bucket = Bucket(rate.burst, now)
    at = max(bucket.at, now)
    tokens = min(rate.burst, bucket.tokens + (at - bucket.at) * rate.per_s)
    if tokens >= cost:
        return Bucket(tokens - cost, at), True
    return Bucket(tokens, at), False


class Budgets:
    """One :class:`Bucket` per login at ``rate``, thread-safe; ``refused`` counts refusals per login.

    Bounded: at most ``max_logins`` buckets are kept. Past that, buckets that have filled up again are
    forgotten (a full bucket is what a login never seen gets); if none has, a new login is refused
    (counted under ``""``) until one does, so made-up names cannot grow the map."""

    def __init__(self, rate: Rate, *, max_logins: int = 1024) -> None:
        self.rate = rate
        self.max_logins = max_logins
        self.refused: Counter[str] = Counter()
        self._buckets: dict[str, Bucket] = {}
        self._lock = threading.Lock()

    def allow(self, login: str, now: float, cost: float = 1.0) -> bool:
        """Whether ``login`` may have one more answer at ``now`` (spent from her bucket if so)."""
        with self._lock:
            bucket = self._buckets.get(login)
            if bucket is None and len(self._buckets) >= self.max_logins:
                self._prune(now)
                if len(self._buckets) >= self.max_logins:
                    self.refused[""] += 1
                    return False
            bucket, ok = take(bucket, self.rate, now, cost)
            self._buckets[login] = bucket
            if not ok:
                self.refused[login] += 1
            return ok

    def _prune(self, now: float) -> None:
        full = [k for k, b in self._buckets.items() if b.tokens + (now - b.at) * self.rate.per_s >= self.rate.burst]
        for k in full:
            del self._buckets[k]

    def refusal(self, login: str, what: str) -> str:
        """The reason a refused ``login`` reads: the word, her budget, and what to do."""
        return (
            f"{RATE_LIMITED}: {login} asked more {what} than her budget of {self.rate}; "
            f"the rest are refused until she slows down"
        )
