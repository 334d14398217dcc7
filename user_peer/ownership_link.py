"""The user API's side of ownership: a thin adapter over ``ownership.OwnershipClient``.

The protocol (requests, leases, renewals, replicas) lives in ``ownership/``;
this adapter turns its answers into the API's exceptions and keeps the
latest record of each object for the UI.
"""

from __future__ import annotations

import logging
import threading
from typing import Any, Callable

from fabric import keys
from fabric.messages import OwnershipRecord
from fabric.session import Fabric
from user_peer.errors import NotOwner, Timeout

log = logging.getLogger("robofabric.user")

__all__ = ["OwnershipLink"]


def _get(obj: Any, *names: str, default: Any = None) -> Any:
    for n in names:
        if hasattr(obj, n):
            return getattr(obj, n)
        if isinstance(obj, dict) and n in obj:
            return obj[n]
    return default


class OwnershipLink:
    """Requests and releases through the ownership client; replicas of every ``own/*`` record."""

    def __init__(self, fab: Fabric, user: str, *, on_record: Callable[[str, Any], None] | None = None) -> None:
        self.fab = fab
        self.user = user
        self._records: dict[str, OwnershipRecord] = {}
        self._lock = threading.Lock()
        self._on_record = on_record
        self._client: Any = None
        fab.subscribe(keys.own_all(fab.world), self._on, expected=OwnershipRecord)
        try:
            for rep in fab.query(keys.own_all(fab.world), timeout=1.0, all_replies=True):
                if isinstance(rep.message, OwnershipRecord):
                    self._on(rep.key, rep.message)
        except Exception:
            pass  # no authority yet: records arrive when it publishes

    @property
    def client(self) -> Any:
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
        with self._lock:
            rec = self._records.get(obj)
        if self._client is not None:
            other = self._client_record(obj)
            if other is not None and (rec is None or other.epoch > rec.epoch):
                return other
        return rec

    def _client_record(self, obj: str) -> OwnershipRecord | None:
        for name in ("record", "replica"):
            fn = getattr(self._client, name, None)
            if callable(fn):
                try:
                    r = fn(obj)
                    return r if isinstance(r, OwnershipRecord) else None
                except Exception:
                    return None
        return None

    def request(self, obj: str, *, timeout: float, wait: bool = False) -> int:
        """Own ``obj`` and return the epoch, or raise :class:`NotOwner` with the authority's reason."""
        try:
            answer = self.client.request(obj, timeout=timeout, wait=wait) if wait else self.client.request(obj, timeout=timeout)
        except TimeoutError as exc:
            raise Timeout(f"no ownership answer for {obj} within {timeout:.1f} s: {exc}") from None
        granted = _get(answer, "granted", "ok", default=None)
        epoch = _get(answer, "epoch", default=None)
        reason = _get(answer, "reason", default="")
        record = _get(answer, "record", default=None)
        if isinstance(record, OwnershipRecord):
            self._on(keys.own(self.fab.world, obj), record)
        if granted is None and isinstance(answer, int):
            granted, epoch = True, answer
        if not granted:
            raise NotOwner(f"{obj} not granted to {self.user}: {reason or 'denied'}")
        return int(epoch if epoch is not None else 0)

    def release(self, obj: str, *, timeout: float) -> None:
        self.client.release(obj, timeout=timeout)

    def close(self) -> None:
        if self._client is not None:
            close = getattr(self._client, "close", None)
            if callable(close):
                close()
