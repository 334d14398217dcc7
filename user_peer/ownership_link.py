"""The user API's side of ownership: a thin adapter over ``ownership.OwnershipClient``.

The protocol (requests, leases, renewals, replicas) lives in ``ownership/``;
this adapter turns its answers into the API's exceptions and keeps the
latest record of each object for the UI.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING, Any, Callable

from fabric import keys
from fabric.messages import OwnershipRecord
from fabric.session import Fabric, ServiceError
from user_peer.errors import NotOwner, Timeout

if TYPE_CHECKING:
    from ownership.client import Outcome, OwnershipClient

log = logging.getLogger("robofabric.user")

__all__ = ["OwnershipLink"]


class OwnershipLink:
    """Requests and releases through the ownership client; replicas of every ``own/*`` record."""

    def __init__(self, fab: Fabric, user: str, *, on_record: Callable[[str, Any], None] | None = None) -> None:
        self.fab = fab
        self.user = user
        self._records: dict[str, OwnershipRecord] = {}
        self._lock = threading.Lock()
        self._on_record = on_record
        self._client: OwnershipClient | None = None
        fab.subscribe(keys.own_all(fab.world), self._on, expected=OwnershipRecord)
        try:
            for rep in fab.query(keys.own_all(fab.world), timeout=1.0, all_replies=True):
                if isinstance(rep.message, OwnershipRecord):
                    self._on(rep.key, rep.message)
        except Exception:
            pass  # no authority yet: records arrive when it publishes

    @property
    def client(self) -> "OwnershipClient":
        if self._client is None:
            try:
                from ownership import OwnershipClient
            except ImportError as exc:
                raise NotOwner(f"ownership is not available in this installation ({exc})") from None
            self._client = OwnershipClient(self.fab, self.user)
        return self._client

    def _on(self, key: str, rec: OwnershipRecord) -> None:
        with self._lock:
            old = self._records.get(rec.object)
            if old is not None and rec.epoch < old.epoch:
                return  # late duplicate of an older record
            self._records[rec.object] = rec
        if self._on_record is not None:
            self._on_record(key, rec)

    def record(self, obj: str) -> OwnershipRecord | None:
        """The newest record of ``obj`` seen by the subscription or by the client's replies."""
        with self._lock:
            rec = self._records.get(obj)
        other = self._client.record(obj) if self._client is not None else None
        if other is not None and (rec is None or other.epoch > rec.epoch):
            return other
        return rec

    def _ask(self, op: str, obj: str, timeout: float, wait: bool = False) -> Outcome:
        """One request to the authority; its silence is :class:`Timeout`, its refusal :class:`NotOwner`."""
        client = self.client
        try:
            out = client.request(obj, timeout=timeout, wait=wait) if op == "request" else client.release(obj, timeout=timeout)
        except ServiceError as exc:
            if exc.reason.startswith("no reply"):
                raise Timeout(f"no ownership answer for {obj} within {timeout:.1f} s (is the sim peer, its authority, running?)") from None
            raise NotOwner(f"{obj}: {exc.reason}") from None
        if out.record is not None:
            self._on(keys.own(self.fab.world, obj), out.record)
        return out

    def request(self, obj: str, *, timeout: float, wait: bool = False) -> int:
        """Own ``obj`` and return the epoch, or raise :class:`NotOwner` with the authority's answer."""
        out = self._ask("request", obj, timeout, wait)
        if not out.granted:
            raise NotOwner(f"{obj} not granted to {self.user}: {out}")
        return out.epoch

    def release(self, obj: str, *, timeout: float) -> None:
        self._ask("release", obj, timeout)

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
