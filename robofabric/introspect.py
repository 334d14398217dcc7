"""What is live on the keys of a world: per key its type, publishers, message count, rate and bandwidth.

:class:`KeyObserver` is pure: feed it ``(key, payload, t)`` samples (``t`` in monotonic seconds,
passed in) and take a :meth:`~KeyObserver.snapshot`. ``robofabric list`` and ``robofabric info
KEY`` (:mod:`robofabric.introspect_cli`) feed it from a Zenoh subscriber for a short window. The
type and the publisher come from the payload itself (the message's type name and its header's
``source``), without a full decode, so watching a busy world stays cheap.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import msgpack

from fabric import keys
from fabric.recording.format import peek

__all__ = ["KeyStats", "KeyObserver", "source_of"]


def source_of(payload: bytes) -> str:
    """The ``header.source`` of a fabric message ("" when it has none or is not a fabric message).

    Headers of any version: the five fields of the first one (``Header, stamp, wall_ns, seq, source``)
    lead, and whatever a later version appends (``term`` today) is not looked at."""
    try:
        msg = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:
        return ""
    if isinstance(msg, list) and msg:
        head = msg[-1]
        if isinstance(head, list) and len(head) >= 5 and head[0] == "Header" and isinstance(head[4], str):
            return head[4]
    return ""


@dataclass(frozen=True, slots=True)
class KeyStats:
    """One key over the observation window."""

    key: str
    types: tuple[str, ...]
    publishers: tuple[str, ...]
    messages: int
    rate_hz: float
    bytes_per_s: float
    last_bytes: int
    latched: bool

    def to_json(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "type": self.types[0] if len(self.types) == 1 else list(self.types),
            "publishers": list(self.publishers),
            "messages": self.messages,
            "rate_hz": round(self.rate_hz, 3),
            "bytes_per_s": round(self.bytes_per_s, 1),
            "last_bytes": self.last_bytes,
            "latched": self.latched,
        }


@dataclass
class _Acc:
    types: dict[str, None] = field(default_factory=dict)
    sources: dict[str, None] = field(default_factory=dict)
    n: int = 0
    nbytes: int = 0
    first: float = 0.0
    last: float = 0.0
    last_bytes: int = 0


class KeyObserver:
    """Accumulates samples per key; not thread-safe (the caller holds a lock around ``add``)."""

    def __init__(self) -> None:
        self._keys: dict[str, _Acc] = {}

    def add(self, key: str, payload: bytes, t: float) -> None:
        a = self._keys.get(key)
        if a is None:
            a = self._keys[key] = _Acc(first=t)
        a.types[peek(payload).schema] = None
        src = source_of(payload)
        if src:
            a.sources[src] = None
        a.n += 1
        a.nbytes += len(payload)
        a.last = t
        a.last_bytes = len(payload)

    def snapshot(self) -> list[KeyStats]:
        """Every key seen, sorted; rates over each key's own first-to-last span (0 with one sample)."""
        out = []
        for key in sorted(self._keys):
            a = self._keys[key]
            span = a.last - a.first
            rate = (a.n - 1) / span if a.n > 1 and span > 0 else 0.0
            bw = (a.nbytes - a.last_bytes) / span if a.n > 1 and span > 0 else 0.0
            out.append(
                KeyStats(key, tuple(a.types), tuple(a.sources), a.n, rate, bw, a.last_bytes, keys.is_latched(key))
            )
        return out
