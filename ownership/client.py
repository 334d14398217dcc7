"""A user's side of ownership: requests, releases, automatic renewal, and a replica of the records.

The replica subscribes to ``rf/{world}/own/*`` and queries it once on start, so a
late joiner sees the current owners at once. ``epoch(obj)`` is the fencing token
to stamp on commands. Requests go to the user's own key ``own/{obj}/by/{user}``.

Trust: a record counts only when it comes from the authority (its ``authority`` is a live sim
peer, whose liveliness token only sim identities may declare in a secure world, and the one this
client already follows while that one lives) and its epoch is plausible: never backwards, never
further ahead than the authority could have counted since the last record
(:func:`epoch_plausible`). Anything else is counted in ``counters`` and changes nothing, so a
forged record cannot stop renewals or hide later real ones.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Callable

from fabric import keys
from fabric.limits import validate_user
from fabric.interfaces import NoReply, OwnershipRecord, OwnReply, OwnRequest, ServiceError
from fabric.session import Fabric
from ownership.refresh import Refresher
from ownership.renewal import Renewal

#: Epoch changes the authority can make per second (each is one request, release, expiry or
#: handover it processed) and the slack on top, for :func:`epoch_plausible`. Generous: the
#: authority serves a few thousand requests per second at most on any machine measured.
MAX_EPOCH_RATE = 10_000.0
EPOCH_SLACK = 1_000

RENEW_LIMIT_S = 5.0
"""How long one renewal waits for its answer, at most: a lease is a few seconds, and a renewal still out after
two rounds is sent again beside it (:mod:`ownership.renewal`)."""


def epoch_plausible(
    old: int | None, new: int, elapsed_s: float, *, rate: float = MAX_EPOCH_RATE, slack: int = EPOCH_SLACK
) -> str | None:
    """None when the authority could have moved an object's epoch from ``old`` to ``new`` in
    ``elapsed_s`` seconds, else why not (backwards, or a jump beyond ``slack + rate * elapsed``)."""
    if old is None:
        return None
    if new < old:
        return f"epoch {new} goes back from {old}"
    limit = old + slack + int(rate * max(0.0, elapsed_s))
    if new > limit:
        return f"epoch {new} jumps past {limit}, more than the authority could have issued since {old}"
    return None


__all__ = ["OwnershipClient", "Outcome", "epoch_plausible"]


@dataclass(frozen=True, slots=True)
class Outcome:
    """The answer to a request: granted / denied (reason) / queued at ``position``."""

    outcome: str
    reason: str = ""
    position: int = 0
    epoch: int = 0
    record: OwnershipRecord | None = None

    @property
    def granted(self) -> bool:
        return self.outcome == "granted"

    def __str__(self) -> str:
        if self.outcome == "queued":
            return f"queued at position {self.position} ({self.reason})"
        if self.outcome == "denied":
            return f"denied: {self.reason}"
        return f"{self.outcome} (epoch {self.epoch})" + (f": {self.reason}" if self.reason else "")


class OwnershipClient:
    """One user's ownership handle in one world; renews every ``renew_s`` while it owns something.

    Constructing one follows the records (subscription and a first query); renewals (:mod:`ownership.renewal`)
    run once it is started (``start()`` or ``with OwnershipClient(...) as own:``) and stop on ``close()``.
    The replica of the records is written by Zenoh's callback threads: read it through :meth:`record`,
    :meth:`epoch`, :meth:`owns` or :meth:`snapshot`, which take the lock (it is private for that reason).
    ``clock`` (monotonic seconds) is only used to bound epoch jumps between records."""

    def __init__(
        self,
        fabric: Fabric,
        user: str,
        *,
        renew_s: float = 0.5,
        timeout: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fabric = fabric
        self.user = validate_user(user)  # refused here, not by the authority's decoder after a timeout
        self.timeout = timeout
        self._records: dict[str, OwnershipRecord] = {}
        self.counters: Counter[str] = Counter()
        self._seen_at: dict[str, float] = {}
        self._clock = clock
        self._lock = threading.Lock()
        self._callbacks: list[Callable[[OwnershipRecord], object]] = []
        self.renewal = Renewal(
            self.user,
            lambda obj: self._ask(obj, "renew", timeout=min(self.timeout, RENEW_LIMIT_S)),
            self.snapshot,
            renew_s=renew_s,
            closed=lambda: fabric.closed,
        )
        self._sims: set[str] = set()
        # per object: the sim that is its authority and the term heard from it (several sims may
        # serve one world, each the authority of its own robots with terms of its own: docs/sim.md)
        self._authority_of: dict[str, str] = {}
        self._term_of: dict[str, int] = {}
        self._replaced: dict[str, int] = {}  # a sim whose objects a higher term took over -> that term
        # sims whose records we have heard since their token: the first record of one we did not ask (its
        # authority came up after our query, and our subscription reached it after some of its first
        # publications) makes us ask it for every record, once
        self._heard_from: set[str] = set()
        # a new sim's token, or a first record from a sim, asks every authority again (after the first query below)
        self._refresher = Refresher(self.refresh, name=f"own-refresh-{self.user}")
        fabric.watch_peers(self.sim_seen, kind="sim")
        try:
            self._sims.update(pid for _, pid in fabric.live_peers("sim", timeout=min(timeout, 1.0)))
        except Exception:
            pass  # the watch fills it in
        fabric.subscribe(keys.own_all(fabric.world), self.record_seen, expected=OwnershipRecord)
        self.refresh()
        self._refresher.enable()

    def start(self) -> "OwnershipClient":
        """Start renewing what this user holds, on a daemon thread (once; a second call does nothing)."""
        self.renewal.start()
        return self

    def __enter__(self) -> "OwnershipClient":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ replica

    def sim_seen(self, kind: str, peer_id: str, alive: bool) -> None:
        """A sim's liveliness token came or went (the watch's callback): which sims may be an object's authority."""
        with self._lock:
            new = alive and peer_id not in self._sims
            if alive:
                self._sims.add(peer_id)
            else:
                self._sims.discard(peer_id)
                self._heard_from.discard(peer_id)
                self._replaced.pop(peer_id, None)  # a sim restarted under this id starts its terms afresh
        if new:  # its records may have come before its token and been refused as foreign: ask again
            self._refresher.ask()

    def refresh(self) -> None:
        """Query the authority for every record (late join)."""
        try:
            for rep in self.fabric.rpc.query(
                keys.own_all(self.fabric.world), timeout=self.timeout, expected=OwnershipRecord, all_replies=True
            ):
                self.record_seen(rep.key, rep.message)
        except ServiceError:
            pass  # no authority yet: the subscription fills the replica when one appears

    def _refusal(self, rec: OwnershipRecord, now: float) -> str | None:
        """Why ``rec`` is not the authority's word (None when it is); call with the lock held."""
        if rec.authority not in self._sims:
            return "foreign"  # not a live sim peer: not an authority at all
        term = rec.header.term
        if not self.fabric.sim_fence.believe(term, rec.authority, (rec.object,)):
            return "stale"  # a lower term: a primary that lost the world and has not noticed yet
        if term < self._replaced.get(rec.authority, 0):
            return "stale"  # a primary whose shard a standby took over (a record of another of its objects)
        authority = self._authority_of.get(rec.object)
        newer = term > self._term_of.get(rec.object, 0)  # a standby took the object's shard over: it speaks for it now
        if not newer and authority is not None and rec.authority != authority and authority in self._sims:
            return "foreign"  # another sim speaking for an object of the one we follow for it
        old = self._records.get(rec.object)
        if old is not None and old.authority != rec.authority:
            old = None  # a new authority (the old one left): its own epochs
        if old is not None and old.epoch == rec.epoch and old.header.wall_ns > rec.header.wall_ns:
            return "stale"  # an older record (query answer racing a publication)
        why = epoch_plausible(None if old is None else old.epoch, rec.epoch, now - self._seen_at.get(rec.object, now))
        if why is not None:
            return "stale" if rec.epoch < (old.epoch if old else 0) else "implausible"
        return None

    def record_seen(self, key: str, rec: OwnershipRecord) -> None:
        """A record as it arrives (the subscription's callback, or a query's reply): kept if it is its object's authority's
        word (a live sim, a term not below the one believed, a plausible epoch), counted and left out otherwise."""
        now = self._clock()
        with self._lock:
            why = self._refusal(rec, now)
            if why is not None:
                self.counters[f"records_{why}"] += 1
                return
            before = self._authority_of.get(rec.object)
            if before is not None and before != rec.authority and rec.header.term > self._term_of.get(rec.object, 0):
                if len(self._replaced) < 256 or before in self._replaced:  # bounded: made-up authorities
                    self._replaced[before] = max(self._replaced.get(before, 0), rec.header.term)
            self._authority_of[rec.object] = rec.authority
            self._term_of[rec.object] = max(self._term_of.get(rec.object, 0), rec.header.term)
            self._records[rec.object] = rec
            self._seen_at[rec.object] = now
            callbacks = list(self._callbacks)
            ask = rec.authority not in self._heard_from
            self._heard_from.add(rec.authority)  # bounded: only live sims' records get here
        if ask:
            self._refresher.ask()
        for cb in callbacks:
            cb(rec)

    def on_change(self, callback: Callable[[OwnershipRecord], object]) -> None:
        with self._lock:
            self._callbacks.append(callback)

    def snapshot(self) -> dict[str, OwnershipRecord]:
        """A copy of the trusted records, taken under the lock."""
        with self._lock:
            return dict(self._records)

    def epoch(self, obj: str) -> int:
        rec = self.record(obj)
        return rec.epoch if rec is not None else 0

    def owns(self, obj: str) -> bool:
        rec = self.record(obj)
        return rec is not None and rec.owner == self.user

    # ------------------------------------------------------------------ requests

    def record(self, obj: str) -> OwnershipRecord | None:
        with self._lock:
            return self._records.get(obj)

    def _ask(self, obj: str, op: str, wait: bool = False, timeout: float | None = None) -> OwnReply:
        """One request to the authority. The replica may still be filling (a user joining while records
        arrive): an object it does not know is asked all the same, and only the authority's silence about
        it is read as 'unknown'."""
        req = OwnRequest(op, self.user, wait, header=self.fabric.header("own-req"))
        key = keys.own_request(self.fabric.world, obj, self.user)
        limit = timeout or self.timeout
        try:
            reply: OwnReply = self.fabric.rpc.call(key, req, timeout=limit, expected=OwnReply)
        except NoReply as exc:
            known = self.snapshot()
            if known and obj not in known and exc.nobody:  # no authority serves it (not one silent)
                raise ServiceError(
                    f"unknown object {obj!r}: no authority serves it (known: {', '.join(sorted(known))})"
                ) from None
            raise
        self.record_seen(keys.own(self.fabric.world, obj), reply.record)
        return reply

    def request(self, obj: str, *, wait: bool = False, timeout: float | None = None) -> Outcome:
        r = self._ask(obj, "request", wait, timeout)
        if r.outcome == "granted":
            self.renewal.hold(obj)
        return Outcome(r.outcome, r.reason, r.position, r.record.epoch, r.record)

    def release(self, obj: str, *, timeout: float | None = None) -> Outcome:
        self.renewal.drop(obj)
        r = self._ask(obj, "release", timeout=timeout)
        return Outcome(r.outcome, r.reason, r.position, r.record.epoch, r.record)

    def staff(self, obj: str, op: str, *, to: str = "", timeout: float | None = None) -> Outcome:
        """An instructor's action on ``obj`` (:data:`fabric.interfaces.STAFF_OPS`, :mod:`ownership.staff`) in this
        client's login: ``done`` or ``denied`` with the reason. A class's router passes it from instructor logins
        only; from anyone else it is dropped and :class:`~fabric.interfaces.NoReply` comes after ``timeout``."""
        req = OwnRequest(op, self.user, header=self.fabric.header("own-staff"), to=to)
        r: OwnReply = self.fabric.rpc.call(
            keys.own_staff(self.fabric.world, obj, self.user), req, timeout=timeout or self.timeout, expected=OwnReply
        )
        self.record_seen(keys.own(self.fabric.world, obj), r.record)
        return Outcome(r.outcome, r.reason, r.position, r.record.epoch, r.record)

    def close(self) -> None:
        """No more renewals nor refreshes; waits (up to 2 s) for a renewal round under way."""
        self._refresher.close()
        self.renewal.close()
