"""The events a user peer has seen, and which of them may change what its program does.

Only an event from its object's authority can refuse a command here: one that came on a key only sims may
write (``fabric.fencing.is_authority_event``; never ``event/decode/by/*``, which any login writes) from a
live sim that is the authority of the object it names. The rest is display-only (the TUI marks it). Events
are judged by their arrival here, never by the sender's clock.

:func:`describe` is the one way an event is put into words for a person (the console's log, the terminal UI's
status line): every field is its writer's text, escaped and capped (:func:`fabric.text.one_line`), so the words
are one line whatever a decode report holds.
"""

from __future__ import annotations

import threading
from typing import Callable

from fabric.fencing import is_authority_event
from fabric.interfaces import REJECT_KINDS, Event, OwnershipRecord
from fabric.text import one_line

__all__ = ["EventLog", "describe"]

KEPT = 1000
"""Events kept; past this, the oldest half is dropped."""


def describe(ev: Event) -> str:
    """``KIND OBJECT [USER]: REASON`` on one line, each field escaped and capped (a 4 KiB reason shows its first
    200 characters): at most about 350 characters whatever the event holds."""
    return (
        one_line(ev.kind, 32)
        + (f" {one_line(ev.object, 48)}" if ev.object else "")
        + (f" [{one_line(ev.user, 48)}]" if ev.user else "")
        + (f": {one_line(ev.reason)}" if ev.reason else "")
    )


class EventLog:
    """``live_sim(peer)``: whether that sim peer is alive now; ``record(object)``: the object's ownership record
    as this user knows it (None if unknown); ``then(key, event)``: called for each event after it is logged."""

    def __init__(
        self,
        user: str,
        *,
        live_sim: Callable[[str], bool],
        record: Callable[[str], OwnershipRecord | None],
        then: Callable[[str, Event], None],
    ) -> None:
        self.user = user
        self.events: list[Event] = []
        self.untrusted = 0  # events acted on by nothing: any login may write their keys, or not the authority's
        self._live_sim = live_sim
        self._record = record
        self._then = then
        self._log: list[tuple[int, Event, bool]] = []  # (local arrival number, event, from its authority)
        self._seen = 0
        self._lock = threading.Lock()

    def from_authority(self, key: str, ev: Event) -> bool:
        """Whether ``ev`` may change what this user's program does (see the module's docstring)."""
        if not is_authority_event(key):
            return False
        source = ev.header.source
        if not self._live_sim(source):
            return False
        rec = self._record(ev.object) if ev.object else None
        return rec is None or rec.authority == source

    def receive(self, key: str, ev: Event) -> None:
        """An event as it arrives (the subscriber's callback)."""
        trusted = self.from_authority(key, ev)
        with self._lock:
            self._seen += 1
            self.events.append(ev)
            self._log.append((self._seen, ev, trusted))
            if not trusted:
                self.untrusted += 1
            if len(self.events) > KEPT:
                del self.events[: KEPT // 2]
                del self._log[: KEPT // 2]
        self._then(key, ev)

    def mark(self) -> int:
        """How many events have arrived so far: pass it to :meth:`rejections` to see only later ones."""
        with self._lock:
            return self._seen

    def rejections(self, robot: str, since: int) -> list[Event]:
        """Events from ``robot``'s authority refusing this user's commands to it that arrived after ``since``
        (a :meth:`mark`)."""
        with self._lock:
            return [
                e
                for n, e, trusted in self._log
                if trusted and n > since and e.object == robot and e.user == self.user and e.kind in REJECT_KINDS
            ]

    def authority_events(self, since: int, until: int, kinds: frozenset[str]) -> list[Event]:
        """Events of ``kinds`` from their object's authority that arrived after mark ``since`` and up to mark
        ``until`` (two :meth:`mark` calls: each event read once by one who reads from mark to mark), whoever they
        concern (a bumper stop names no user)."""
        with self._lock:
            return [e for n, e, trusted in self._log if trusted and since < n <= until and e.kind in kinds]

    def recent(self, limit: int = 20) -> list[tuple[Event, bool]]:
        """The latest ``limit`` events, oldest first, each with whether it came from its object's authority."""
        with self._lock:
            return [(e, trusted) for _, e, trusted in self._log[-limit:]]
