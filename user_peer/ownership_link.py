"""The user API's side of ownership: a thin adapter over ``ownership.OwnershipClient``.

The protocol (requests, leases, renewals, replicas) lives in ``ownership/``;
this adapter turns its answers into the API's exceptions and keeps the
latest record of each object for the UI.
"""

from __future__ import annotations

import logging
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
    """Requests and releases through the ownership client; its replica of every ``own/*`` record.

    The client's replica takes records only from the authority (``ownership.client``): a forged
    record must not change the epoch this user stamps on commands nor what the UI shows."""

    def __init__(self, fab: Fabric, user: str, *, on_record: Callable[[str, Any], None] | None = None) -> None:
        from ownership import OwnershipClient

        self.fab = fab
        self.user = user
        self._on_record = on_record
        self._client = OwnershipClient(fab, user, timeout=1.0)
        self._client.timeout = 2.0  # the first refresh waits 1 s at most when no authority runs yet
        self._client.on_change(lambda rec: self._on(keys.own(fab.world, rec.object), rec))
        for rec in list(self._client.records.values()):
            self._on(keys.own(fab.world, rec.object), rec)

    @property
    def client(self) -> "OwnershipClient":
        return self._client

    def _on(self, key: str, rec: OwnershipRecord) -> None:
        if self._on_record is not None:
            self._on_record(key, rec)

    def record(self, obj: str) -> OwnershipRecord | None:
        """The newest record of ``obj`` from the authority."""
        return self._client.record(obj)

    def _ask(self, op: str, obj: str, timeout: float, wait: bool = False) -> Outcome:
        """One request to the authority; its silence is :class:`Timeout`, its refusal :class:`NotOwner`."""
        client = self.client
        try:
            out = client.request(obj, timeout=timeout, wait=wait) if op == "request" else client.release(obj, timeout=timeout)
        except ServiceError as exc:
            if exc.reason.startswith("no reply"):
                raise Timeout(f"no ownership answer for {obj} within {timeout:.1f} s (is the sim peer, its authority, running?)") from None
            raise NotOwner(f"{obj}: {exc.reason}") from None
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
        self._client.close()
