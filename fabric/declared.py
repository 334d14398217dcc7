"""What a peer subscribes to and serves, told by the peer itself on its own token's key.

``robofabric list``, ``info`` and ``ps -v`` name who subscribes to a key and who serves a service. They used to
ask the router's admin space (``@/ROUTER/router/{subscriber,queryable,token}/**``), and that can stop a router
for good: zenoh (1.10.2, and its main branch as of 2026-08) answers those keys while holding its routing tables'
read lock, and takes it again to route each reply. A declaration from any other session (a student's page
following a robot) queued between the two reads waits behind the first, the second waits behind it, and every
session of that router stops (zenoh pull request 2619, open). It hung the test suite twice (docs/testing.md).

So each :class:`fabric.Fabric` with a token answers a plain query on that token's key, ``rf/W/peer/KIND/ID``,
with what its code declared through it (:meth:`fabric.Fabric.subscribe_raw`, ``rpc.serve``): a JSON document
``{"kind", "id", "subscribers", "queryables"}``. A liveliness token and a queryable on the same key do not meet
(liveliness has a key space of its own). The router's admin space stays on for its own entry (``@/ROUTER/router``,
answered without that lock): a standby sim asks it whether its link is up (``sim_peer.replica.roles``).

What is told is what the code asked for, not zenoh's own declarations beneath it (a latched publisher's cache, the
fence watch's subscription): those were noise in ``ps -v``. A declaration undeclared since is left out.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass
from typing import Any

__all__ = ["MAX_TOLD", "Told", "Declared", "encode_told", "decode_told", "is_declared"]

MAX_TOLD = 1024
"""Expressions told per kind (subscribers, queryables) at most: a reply stays small whatever a peer declared."""
_MAX_EXPR = 1024  # characters of one expression a reader keeps (zenoh's keys are longer only when made up)


@dataclass(frozen=True, slots=True)
class Told:
    """One peer's answer: its kind and id (as its token says), and the expressions it subscribes to and serves."""

    kind: str
    id: str
    subscribers: tuple[str, ...]
    queryables: tuple[str, ...]


def encode_told(told: Told) -> bytes:
    return json.dumps(
        {
            "kind": told.kind,
            "id": told.id,
            "subscribers": list(told.subscribers[:MAX_TOLD]),
            "queryables": list(told.queryables[:MAX_TOLD]),
        },
        separators=(",", ":"),
    ).encode()


def decode_told(payload: bytes) -> Told | None:
    """The answer in ``payload``, or None when it is not one (any login may answer on its own token's key)."""
    try:
        doc = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        return None
    if not isinstance(doc, dict):
        return None
    kind, ident = doc.get("kind"), doc.get("id")
    if not isinstance(kind, str) or not isinstance(ident, str):
        return None
    lists: list[tuple[str, ...]] = []
    for name in ("subscribers", "queryables"):
        v = doc.get(name)
        if not isinstance(v, list):
            return None
        lists.append(tuple(sorted({e for e in v[:MAX_TOLD] if isinstance(e, str) and 0 < len(e) <= _MAX_EXPR})))
    return Told(kind, ident, lists[0], lists[1])


def is_declared(handle: Any) -> bool:
    """Whether ``handle`` (a zenoh subscriber or queryable, or a :class:`fabric.history.LatestThenLive`) is still
    declared: zenoh's handles refuse ``key_expr`` once undeclared (or once their session closed)."""
    undeclared = getattr(handle, "undeclared", None)
    if isinstance(undeclared, bool):
        return not undeclared
    try:
        return handle.key_expr is not None
    except Exception:
        return False


class Declared:
    """One session's subscriptions and services as its code declared them; undeclared ones drop out when read."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._items: list[tuple[str, str, Any]] = []  # (what: "subscriber" | "queryable", expression, handle)
        self._prune_at = 64  # a page that follows robot after robot for hours undeclares as much as it declares

    def add(self, what: str, expr: str, handle: Any) -> None:
        if what not in ("subscriber", "queryable"):
            raise ValueError(f"what must be 'subscriber' or 'queryable', not {what!r}")
        with self._lock:
            self._items.append((what, expr, handle))
            if len(self._items) >= self._prune_at:
                self._items = [item for item in self._items if is_declared(item[2])]
                self._prune_at = max(64, 2 * len(self._items))

    def now(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(subscribed expressions, served expressions) declared and not undeclared since, sorted, each once."""
        with self._lock:
            self._items = [item for item in self._items if is_declared(item[2])]
            items = list(self._items)
        subs = sorted({e for w, e, _ in items if w == "subscriber"})
        served = sorted({e for w, e, _ in items if w == "queryable"})
        return tuple(subs), tuple(served)
