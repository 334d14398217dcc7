"""What a client may make the fabric hold: user names, quoted client text, per-key log and event rates.

Every peer trusts nothing a client sends. Three habits live here so that each
is checked in one place:

* :func:`validate_user` - a user name is at most :data:`MAX_USER_LEN` characters of a safe
  alphabet. The codec checks it on every message that names a user (``Command.user``,
  ``OwnRequest.user``), so a 1 MB "user" never reaches a counter, a queue or a key.
* :func:`quote` - error texts quote at most :data:`QUOTE_LEN` characters of anything a client sent.
* :class:`RateLimiter` - "at most once per key per interval, with a count of what was suppressed",
  for logs and events about bad input. It holds at most ``max_keys`` keys, so a flood of made-up
  keys cannot grow it: the oldest key is forgotten first.

Pure: time is passed in as a value.
"""

from __future__ import annotations

import queue
import re
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

__all__ = [
    "MAX_USER_LEN",
    "QUOTE_LEN",
    "USER_PATTERN",
    "validate_user",
    "is_valid_user",
    "quote",
    "clip",
    "RateLimiter",
    "ReportVerdict",
    "put_dropping_oldest",
]

MAX_USER_LEN = 64
QUOTE_LEN = 200
USER_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}")
"""Letters, digits, ``_``, ``.`` and ``-``; not starting with ``.`` or ``-`` (a key chunk, a file name,
a terminal line: a user name is all of these somewhere)."""


def quote(value: object, limit: int = QUOTE_LEN) -> str:
    """``repr`` of ``value`` cut to about ``limit`` characters, saying how long it was when cut."""
    sized = isinstance(value, (str, bytes, bytearray))
    text = repr(value[: limit + 1]) if sized else repr(value)  # type: ignore[index]
    if len(text) <= limit:
        return text
    return text[:limit] + (f"... ({len(value)} characters)" if sized else "...")  # type: ignore[arg-type]


def clip(text: str, limit: int = QUOTE_LEN) -> str:
    """``text`` cut to ``limit`` characters (an error text that may hold client data)."""
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def is_valid_user(name: object) -> bool:
    return isinstance(name, str) and USER_PATTERN.fullmatch(name) is not None


def validate_user(name: object, *, what: str = "user") -> str:
    """Return ``name`` if it is a valid user name, else raise ``ValueError`` saying why (quoting ≤ 200 chars)."""
    if not isinstance(name, str):
        raise ValueError(f"{what}: must be a string, got {type(name).__name__}")
    if not name:
        raise ValueError(f"{what}: must not be empty")
    if len(name) > MAX_USER_LEN:
        raise ValueError(f"{what}: {len(name)} characters is too long (at most {MAX_USER_LEN})")
    if USER_PATTERN.fullmatch(name) is None:
        raise ValueError(f"{what}: {quote(name)} may hold only letters, digits, '_', '.' and '-' (not first)")
    return name


@dataclass(frozen=True, slots=True)
class ReportVerdict:
    """Whether to report now, and how many reports on this key were suppressed since the last one."""

    report: bool
    suppressed: int = 0

    def __bool__(self) -> bool:
        return self.report


class RateLimiter:
    """At most ``burst`` reports per key per ``interval`` seconds; counts what it suppressed.

    A fixed window per key: the first ``burst`` reports of a window go through, the rest are
    counted, and the first report of a later window carries that count. At most ``max_keys``
    keys are remembered (least recently reported first out), so made-up keys cannot grow it;
    callers still pass keys of a fixed vocabulary (a subscription, a robot and a reason), never
    raw client text. Not thread-safe by itself.
    """

    def __init__(self, interval: float = 5.0, *, burst: int = 1, max_keys: int = 256) -> None:
        if interval < 0 or max_keys < 1 or burst < 1:
            raise ValueError("interval must be >= 0, burst and max_keys >= 1")
        self.interval = float(interval)
        self.burst = int(burst)
        self.max_keys = int(max_keys)
        self._windows: OrderedDict[str, list[Any]] = OrderedDict()  # key -> [window start, reported, suppressed]

    def __len__(self) -> int:
        return len(self._windows)

    def check(self, key: str, now: float) -> ReportVerdict:
        """Report ``key`` now? ``now`` is any monotonic time in seconds."""
        w = self._windows.get(key)
        if w is None:
            self._windows[key] = [now, 1, 0]
            while len(self._windows) > self.max_keys:
                self._windows.popitem(last=False)
            return ReportVerdict(True, 0)
        if now - w[0] >= self.interval:
            suppressed = w[2]
            w[0], w[1], w[2] = now, 1, 0
            self._windows.move_to_end(key)
            return ReportVerdict(True, suppressed)
        if w[1] < self.burst:
            w[1] += 1
            suppressed, w[2] = w[2], 0
            return ReportVerdict(True, suppressed)
        w[2] += 1
        return ReportVerdict(False)

    def pending(self) -> dict[str, int]:
        """Keys with suppressed reports not yet told, and how many."""
        return {k: w[2] for k, w in self._windows.items() if w[2]}


def put_dropping_oldest(q: "queue.Queue[Any]", item: object) -> int:
    """Put ``item`` on a bounded queue, dropping the oldest entries to make room, and return how many were
    dropped: a slow consumer loses old samples and never blocks the producer (zenoh's callback thread)."""
    dropped = 0
    while True:
        try:
            q.put_nowait(item)
            return dropped
        except queue.Full:
            try:
                q.get_nowait()
                dropped += 1
            except queue.Empty:
                pass
