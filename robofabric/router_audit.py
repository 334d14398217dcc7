"""Counting what a router's access control refused (``robofabric router --audit``).

zenoh counts refusals nowhere a program can read; it only logs, at TRACE level and from Rust to
the process's standard output, each permission decision
(``zenoh::net::routing::interceptor::access_control``: ``... Username(mallory) ... is
unauthorized to Put (ingress) on KEY``) and each message its interceptors drop
(``zenoh::net::routing::interceptor: Msg intercepted!``). Decisions are also logged when zenoh
computes and caches the permissions of a declared key (for every kind of message at once), so a
refusal is a dropped message, attributed to the last decision logged on the same thread.

The audit turns that log on for these modules, takes file descriptor 1 into a pipe, counts the
drops by (login, message, key), passes every other line through, and prints a one-line summary per
interval. TRACE also logs every *authorized* decision, so the audit costs the router CPU in
proportion to the traffic: a diagnostic for a class, not a default (docs/security.md).

zenoh writes a key as it is, and a key may hold a newline: a liveliness token's id with a newline and an
audit-like line after it printed that line as the audit's own. Here a log record starts with its timestamp;
a line that does not is the rest of the record before it (:data:`_RECORD`): it is never read as a decision or
a drop, it ends the key of the refusal it continues (escaped in the summary), and anything else passed
through is shown escaped, a continuation behind :data:`CONTINUED`. The audit's own lines start with
``refused``, which no passed-through line can. What a counterfeit record inside a key could still do is be
counted (the counts are the log's word, a diagnostic): it can no longer look like the audit's summary.
"""

from __future__ import annotations

import os
import re
import sys
import threading
from collections import Counter
from dataclasses import dataclass
from typing import Callable, TextIO

from fabric.text import one_line

__all__ = ["Refusal", "RefusalCounter", "parse_refusal", "summary", "shown", "Audit", "LOG_FILTER", "CONTINUED"]

LOG_FILTER = "error,zenoh::net::routing::interceptor=trace"
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
# the message is one word (Put, Query, Reply) or, for declarations, several: "Declare Queryable",
# "Declare/Undeclare Liveliness Token" (zenoh 1.10); named as in the config's rules (declare_queryable)
_REFUSED = re.compile(r"is unauthorized to (?P<message>\w[\w/ ]*?) \((?P<flow>\w+)\) on (?P<key>\S+)")
_SUBJECT = re.compile(r"(?:Username|CertCommonName|CommonName)\((?P<who>[^)]*)\)")
_ACL_LINE = "zenoh::net::routing::interceptor"
_DROPPED = "Msg intercepted!"
_THREAD = re.compile(r"ThreadId\((\d+)\)")
_RECORD = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?Z\s")
"""How a record of zenoh's log starts (after its colours): a line that does not is the rest of the one before."""
CONTINUED = "  ↳ "
"""What a passed-through line that continues the record before it starts with."""


@dataclass(frozen=True, slots=True)
class Refusal:
    """One refused message: who (login or certificate name; ``?`` when the log does not say), what, where."""

    who: str
    message: str
    flow: str
    key: str


UNKNOWN = Refusal("?", "?", "?", "?")  # type: ignore[misc]  # a drop with no decision logged before it


class RefusalCounter:
    """Feed log lines; ``counts`` holds the dropped messages by the decision that dropped them."""

    def __init__(self) -> None:
        self.counts: Counter[Refusal] = Counter()
        self.logins: dict[str, str] = {}  # session zid -> login, from the decisions that name both
        self._last: dict[str, Refusal] = {}
        self.acl_record = False  # whether the record the last line belongs to is access control's
        self._record_thread: str | None = None  # the thread of the last record, when it was a refusal's decision

    def feed(self, line: str) -> Refusal | None:
        """The refusal this line completes (a drop), else None. A line that continues the record before it (a
        key that held a newline) adds to that record's refusal's key and is read no further."""
        text = _ANSI.sub("", line).rstrip("\r\n")
        if not _RECORD.match(text):
            thread = self._record_thread
            if thread is not None and thread in self._last:
                ref = self._last[thread]
                if len(ref.key) < 4096:
                    self._last[thread] = Refusal(ref.who, ref.message, ref.flow, f"{ref.key}\n{text}")
            return None
        self.acl_record = _ACL_LINE in text
        self._record_thread = None
        m = _THREAD.search(text)
        thread = m.group(1) if m else ""
        z = _ZID_WHO.search(line)
        if z is not None and len(self.logins) < 10_000:
            self.logins[z.group("zid")] = z.group("who")
        ref = parse_refusal(line, self.logins)
        if ref is not None:
            self._last[thread] = ref
            self._record_thread = thread
            return None
        if _DROPPED in line:
            ref = self._last.get(thread, UNKNOWN)
            self.counts[ref] += 1
            return ref
        return None


_ZID_WHO = re.compile(r"(?P<zid>[0-9a-f]{8,32}) on \S*?(?:Username|CertCommonName|CommonName)\((?P<who>[^)]*)\)")
_ZID = re.compile(r"(?P<zid>[0-9a-f]{8,32}) is (?:un)?authorized")


def parse_refusal(line: str, logins: dict[str, str] | None = None) -> Refusal | None:
    """The refusal a zenoh access-control log line reports, or None for any other line.

    A decision zenoh took from its cache names the session (zid) only: ``logins`` maps the zids
    seen in earlier lines to their login (:class:`RefusalCounter` keeps it)."""
    text = _ANSI.sub("", line)
    m = _REFUSED.search(text)
    if m is None:
        return None
    who = _SUBJECT.search(text[: m.start()])
    name = who.group("who") if who else None
    if name is None and logins:
        z = _ZID.search(text)
        name = logins.get(z.group("zid")) if z else None
    return Refusal(name or "?", _message_name(m.group("message")), m.group("flow"), m.group("key"))


def _message_name(text: str) -> str:
    """zenoh's words for a message as the access-control rules spell it: ``Declare/Undeclare Queryable``
    and ``Declare Queryable`` -> ``declare_queryable``, ``Declare/Undeclare Liveliness Token`` ->
    ``liveliness_token``, ``Put`` -> ``put``."""
    name = text.lower().replace("declare/undeclare ", "declare ").replace(" ", "_")
    return "liveliness_token" if name == "declare_liveliness_token" else name


class Audit:
    """Capture fd 1, count refusals, print a summary every ``every`` seconds with ``say``.

    Must start before zenoh's logging is initialised (this process's first session)."""

    def __init__(self, every: float = 10.0, say: Callable[[str], None] | None = None) -> None:
        self.every = every
        self.counter = RefusalCounter()
        self._window: Counter[Refusal] = Counter()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        sys.stdout.flush()
        saved = os.dup(1)
        self._out: TextIO = os.fdopen(saved, "w", buffering=1)
        r, w = os.pipe()
        os.dup2(w, 1)
        os.close(w)
        sys.stdout = self._out  # Python's own prints skip the pipe
        self.say = say or (lambda text: print(text, flush=True))
        self._reader = threading.Thread(
            target=self._read, args=(os.fdopen(r, "r", errors="replace"),), name="acl-audit", daemon=True
        )
        self._reader.start()
        self._ticker = threading.Thread(target=self._tick, name="acl-audit-summary", daemon=True)
        self._ticker.start()
        import zenoh

        zenoh.init_log_from_env_or(LOG_FILTER)

    @property
    def total(self) -> Counter[Refusal]:
        with self._lock:
            return Counter(self.counter.counts)

    def _read(self, stream: TextIO) -> None:
        for line in stream:
            with self._lock:
                ref = self.counter.feed(line)
                if ref is not None:
                    self._window[ref] += 1
                passed = ref is None and not self.counter.acl_record
            if passed:  # anything else on fd 1 still reaches the terminal, as text
                self._out.write(shown(line) + "\n")

    def _tick(self) -> None:
        while not self._stop.wait(self.every):
            self.flush()

    def flush(self, *, final: bool = False) -> None:
        with self._lock:
            window = Counter(self.counter.counts) if final else self._window
            self._window = Counter()
        if window:
            self.say(summary(window, prefix="refused in total" if final else f"refused in the last {self.every:g} s"))

    def close(self) -> None:
        self._stop.set()
        self.flush(final=True)


def summary(counts: Counter, *, prefix: str, top: int = 5) -> str:
    """``refused ...: 12 (put 10, query 2); mallory put rf/w/own/arm1 x6; ...`` (the most frequent first), one
    line: logins, messages and keys are escaped and capped (:func:`fabric.text.one_line`)."""
    by_msg: Counter[str] = Counter()
    for ref, n in counts.items():
        by_msg[ref.message] += n
    kinds = ", ".join(f"{one_line(m, 40)} {n}" for m, n in by_msg.most_common())
    worst = "; ".join(
        f"{one_line(r.who, 64)} {one_line(r.message, 40)} {one_line(r.key)} x{n}" for r, n in counts.most_common(top)
    )
    return f"{prefix}: {sum(counts.values())} ({kinds}); {worst}"


def shown(line: str) -> str:
    """A line of fd 1 that is not the audit's, as the audit passes it on: its colours kept off, one line, escaped;
    one that continues the record before it behind :data:`CONTINUED`."""
    text = _ANSI.sub("", line).rstrip("\r\n")
    return one_line(text, 2000) if _RECORD.match(text) else CONTINUED + one_line(text, 2000)
