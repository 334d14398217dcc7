"""The user API's side of ownership: a thin adapter over ``ownership.OwnershipClient``.

The protocol (requests, leases, renewals, replicas) lives in ``ownership/``;
this adapter turns its answers into the API's exceptions, keeps the
latest record of each object for the UI, and tells the user when an object
she owned was taken from her (a lease that ran out, a handover, a partition).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any, Callable

from fabric import keys
from fabric.interfaces import OwnershipRecord, ServiceError
from fabric.session import Fabric
from user_peer.errors import NotOwner, Timeout

if TYPE_CHECKING:
    from ownership.client import Outcome, OwnershipClient

log = logging.getLogger("robofabric.user")

__all__ = ["OwnershipLink"]


class OwnershipLink:
    """Requests and releases through the ownership client; its replica of every ``own/*`` record.

    The client's replica takes records only from the authority (``ownership.client``): a forged
    record must not change the epoch this user stamps on commands nor what the UI shows."""

    def __init__(self, fab: Fabric, user: str, *, on_record: Callable[[str, Any], None] | None = None) -> None:
        from ownership import OwnershipClient

        self.fab = fab
        self.user = user
        self._on_record = on_record
        self._changed = threading.Condition()  # notified on every record the client accepts
        self._lock = threading.Lock()
        self._mine: dict[str, int] = {}  # objects this user owns, by the replica: epoch
        self._releasing: set[str] = set()  # released by this user: their next owner is no loss
        self._lost_callbacks: list[Callable[[str, OwnershipRecord], None]] = []
        self._client = OwnershipClient(fab, user, timeout=1.0).start()
        self._client.timeout = 2.0  # the first refresh waits 1 s at most when no authority runs yet
        self._client.on_change(lambda rec: self._on(keys.own(fab.world, rec.object), rec))
        for rec in self._client.snapshot().values():
            self._on(keys.own(fab.world, rec.object), rec)

    @property
    def client(self) -> "OwnershipClient":
        return self._client

    def on_lost(self, callback: Callable[[str, OwnershipRecord], None]) -> None:
        """``callback(obj, record)`` when an object this user owned passes to another user or becomes
        free without her releasing it (her lease ran out, she was cut off, a handover); ``record`` is
        the authority's new one. A warning is logged as well (``lost ownership of arm1: ...``)."""
        with self._lock:
            self._lost_callbacks.append(callback)

    def _on(self, key: str, rec: OwnershipRecord) -> None:
        with self._changed:
            self._changed.notify_all()
        if self._on_record is not None:
            self._on_record(key, rec)
        self._notice(rec)

    def _notice(self, rec: OwnershipRecord) -> None:
        with self._lock:
            obj = rec.object
            if rec.owner == self.user:
                # a record naming us while a release is on its way (a renewal's answer, a publication) keeps
                # the release voluntary: the next record, free or someone else's, is no loss
                self._mine[obj] = rec.epoch
                return
            held = self._mine.pop(obj, None)
            voluntary = obj in self._releasing
            self._releasing.discard(obj)
            if held is None or voluntary:
                return
            callbacks = list(self._lost_callbacks)
        now = f"now owned by {rec.owner}" if rec.owner else "now free"
        log.warning("lost ownership of %s: %s (epoch %d; it was %d)", obj, now, rec.epoch, held)
        for cb in callbacks:
            try:
                cb(obj, rec)
            except Exception:
                log.exception("ownership-lost callback failed")

    def record(self, obj: str) -> OwnershipRecord | None:
        """The newest record of ``obj`` from the authority."""
        return self._client.record(obj)

    def _ask(self, op: str, obj: str, timeout: float, wait: bool = False) -> Outcome:
        """One request to the authority; its silence is :class:`Timeout`, its refusal :class:`NotOwner`."""
        client = self.client
        try:
            out = (
                client.request(obj, timeout=timeout, wait=wait)
                if op == "request"
                else client.release(obj, timeout=timeout)
            )
        except ServiceError as exc:
            if exc.reason.startswith("no reply"):
                raise Timeout(
                    f"no ownership answer for {obj}: {exc.reason} (is the sim peer, its authority, running?)"
                ) from None
            raise NotOwner(f"{obj}: {exc.reason}") from None
        return out

    def fetch(self, obj: str, *, timeout: float) -> OwnershipRecord | None:
        """The authority's current record of ``obj`` (None when no authority answers: a world without
        ownership, or one not started yet)."""
        self._client.refresh()  # through the client: only the authority's records count (its own time limit)
        return self.record(obj)

    def request(self, obj: str, *, timeout: float, wait: bool = False) -> int:
        """Own ``obj`` and return the epoch.

        Without ``wait``: a refusal raises :class:`NotOwner` with the authority's answer. With ``wait``:
        queued, this waits until the queue place becomes ownership (a record naming this user as owner)
        and returns its epoch; after ``timeout`` it leaves the queue and raises :class:`Timeout`.
        """
        t0 = time.monotonic()
        with self._lock:
            self._releasing.discard(obj)  # asked for again: losing it from now on is a loss
        out = self._ask("request", obj, timeout, wait)
        if out.granted:
            return out.epoch
        if not wait or out.outcome != "queued":
            raise NotOwner(f"{obj} not granted to {self.user}: {out}")
        deadline = t0 + timeout
        while True:
            rec = self.record(obj)
            if rec is not None and rec.owner == self.user:
                return rec.epoch
            left = deadline - time.monotonic()
            if left <= 0:
                break
            with self._changed:
                self._changed.wait(min(left, 0.1))  # a record landing just before the wait costs <= 0.1 s
        waited = time.monotonic() - t0
        with self._lock:
            self._releasing.add(obj)
        try:
            self._ask("release", obj, min(timeout, 2.0))  # leave the queue (or give back a grant that just came)
        except (NotOwner, Timeout) as exc:
            log.info("could not leave the queue of %s: %s", obj, exc)
        where = (
            f"queued at position {rec.queue.index(self.user) + 1}"
            if rec is not None and self.user in rec.queue
            else "queued"
        )
        owner = f"owner {rec.owner}, {rec.state}" if rec is not None and rec.owner else "no owner"
        raise Timeout(
            f"{obj} not granted to {self.user} after {waited:.1f} s of waiting ({where}; {owner}); left the queue"
        )

    def enqueue(self, obj: str, *, timeout: float) -> int:
        """Ask for ``obj`` willing to wait, without waiting: the queue place (1: next), or 0 when granted
        at once; :class:`NotOwner` when refused (a full queue), :class:`Timeout` when no authority answers."""
        with self._lock:
            self._releasing.discard(obj)
        out = self._ask("request", obj, timeout, wait=True)
        if out.granted:
            return 0
        if out.outcome != "queued":
            raise NotOwner(f"{obj} not granted to {self.user}: {out}")
        return out.position

    def release(self, obj: str, *, timeout: float) -> None:
        with self._lock:
            self._releasing.add(obj)
        self._ask("release", obj, timeout)

    def release_all(self, *, timeout: float) -> list[str]:
        """Release every object this user owns or waits for (what ``World.close`` does); returns them.
        Best effort: an authority that does not answer will see the user's token go instead."""
        held = [o for o, r in self._client.snapshot().items() if r.owner == self.user or self.user in r.queue]
        with self._lock:
            self._releasing.update(held)
        done = []
        for obj in held:
            try:
                self._ask("release", obj, timeout)
                done.append(obj)
            except Exception as exc:  # closing must go on
                log.info("could not release %s on close: %s", obj, exc)
        return done

    def close(self) -> None:
        self._client.close()
