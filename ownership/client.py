"""A user's side of ownership: requests, releases, automatic renewal, and a replica of the records.

The replica subscribes to ``rf/{world}/own/*`` and queries it once on start, so a
late joiner sees the current owners at once. ``epoch(obj)`` is the fencing token
to stamp on commands.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Callable

from fabric import keys
from fabric.limits import validate_user
from fabric.messages import OwnershipRecord
from fabric.session import Fabric, ServiceError

from ownership.messages import OwnReply, OwnRequest

__all__ = ["OwnershipClient", "Outcome"]


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
    """One user's ownership handle in one world; renews every ``renew_s`` while it owns something."""

    def __init__(self, fabric: Fabric, user: str, *, renew_s: float = 0.5, timeout: float = 2.0) -> None:
        self.fabric = fabric
        self.user = validate_user(user)  # refused here, not by the authority's decoder after a timeout
        self.timeout = timeout
        self.records: dict[str, OwnershipRecord] = {}
        self._lock = threading.Lock()
        self._callbacks: list[Callable[[OwnershipRecord], None]] = []
        self._stop = threading.Event()
        fabric.subscribe(keys.own_all(fabric.world), self._on_record, expected=OwnershipRecord)
        self.refresh()
        self._renew_s = renew_s
        self._thread = threading.Thread(target=self._renew_loop, name=f"own-renew-{user}", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ replica

    def refresh(self) -> None:
        """Query the authority for every record (late join)."""
        try:
            for rep in self.fabric.query(keys.own_all(self.fabric.world), timeout=self.timeout,
                                         expected=OwnershipRecord, all_replies=True):
                self._on_record(rep.key, rep.message)
        except ServiceError:
            pass  # no authority yet: the subscription fills the replica when one appears

    def _on_record(self, key: str, rec: OwnershipRecord) -> None:
        with self._lock:
            old = self.records.get(rec.object)
            if old is not None and (old.epoch > rec.epoch or (old.epoch == rec.epoch and old.header.wall_ns > rec.header.wall_ns)):
                return  # an older record (query answer racing a publication)
            self.records[rec.object] = rec
            callbacks = list(self._callbacks)
        for cb in callbacks:
            cb(rec)

    def on_change(self, callback: Callable[[OwnershipRecord], None]) -> None:
        with self._lock:
            self._callbacks.append(callback)

    def epoch(self, obj: str) -> int:
        rec = self.records.get(obj)
        return rec.epoch if rec is not None else 0

    def owns(self, obj: str) -> bool:
        rec = self.records.get(obj)
        return rec is not None and rec.owner == self.user

    # ------------------------------------------------------------------ requests

    def record(self, obj: str) -> OwnershipRecord | None:
        return self.records.get(obj)

    def _ask(self, obj: str, op: str, wait: bool = False, timeout: float | None = None) -> OwnReply:
        if self.records and obj not in self.records:
            raise ServiceError(f"unknown object {obj!r} (known: {', '.join(sorted(self.records))})")
        req = OwnRequest(op, self.user, wait, header=self.fabric.header("own-req"))
        reply = self.fabric.call(keys.own(self.fabric.world, obj), req, timeout=timeout or self.timeout, expected=OwnReply)
        self._on_record(keys.own(self.fabric.world, obj), reply.record)
        return reply

    def request(self, obj: str, *, wait: bool = False, timeout: float | None = None) -> Outcome:
        r = self._ask(obj, "request", wait, timeout)
        return Outcome(r.outcome, r.reason, r.position, r.record.epoch, r.record)

    def release(self, obj: str, *, timeout: float | None = None) -> Outcome:
        r = self._ask(obj, "release", timeout=timeout)
        return Outcome(r.outcome, r.reason, r.position, r.record.epoch, r.record)

    def _renew_loop(self) -> None:
        while not self._stop.wait(self._renew_s):
            for obj, rec in list(self.records.items()):
                if rec.owner == self.user and rec.policy == "exclusive":
                    try:
                        self._ask(obj, "renew")
                    except ServiceError:
                        pass

    def close(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
