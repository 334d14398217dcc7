"""How fabric samples map onto MCAP records, shared by the recorder, the reader and the replayer.

One channel per key (topic = the full zenoh key), message encoding ``msgpack``,
schema name = the fabric message type (the first element of the msgpack array)
or ``raw`` for bytes that are not a fabric message: those are recorded anyway,
because a recorder that drops what it does not understand cannot be trusted
to debug the peer that sent it. Peeking is deliberately shallow (no
validation): the recorder must keep up with every stream of a world.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import msgpack

from fabric import keys
from fabric.codec import registered

__all__ = [
    "MESSAGE_ENCODING",
    "RAW_SCHEMA",
    "LIVELINESS_SCHEMA",
    "PROFILE",
    "METADATA_NAME",
    "Peek",
    "peek",
    "schema_data",
    "remap_world",
    "world_of",
]

MESSAGE_ENCODING = "msgpack"
RAW_SCHEMA = "raw"
LIVELINESS_SCHEMA = "liveliness"
PROFILE = "robofabric"
METADATA_NAME = "robofabric"
SCHEMA_ENCODING = "robofabric-msgpack"


@dataclass(frozen=True, slots=True)
class Peek:
    """What a payload says about itself: its type name, and its header's wall time, sequence,
    term and source peer if any."""

    schema: str
    wall_ns: int | None = None
    seq: int | None = None
    term: int = 0
    source: str = ""


_RAW = Peek(RAW_SCHEMA)


def peek(payload: bytes) -> Peek:
    """Type name and header stamps of a fabric payload, or ``raw`` if it is not one (never raises)."""
    try:
        msg = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:
        return _RAW
    if not isinstance(msg, list) or not msg or not isinstance(msg[0], str) or not _known(msg[0]):
        return _RAW
    head = msg[-1]
    if (
        isinstance(head, list)
        and len(head) >= 5  # 6: with the term (Header.term); later versions may add trailing fields
        and head[0] == "Header"
        and isinstance(head[2], int)
        and isinstance(head[3], int)
        and head[2] >= 0
    ):
        term = head[5] if len(head) >= 6 and isinstance(head[5], int) and head[5] >= 0 else 0
        return Peek(msg[0], head[2], head[3], term, head[4] if isinstance(head[4], str) else "")
    return Peek(msg[0])


_TYPES: dict[str, type] = {}


def _known(name: str) -> bool:
    # Refreshed on a miss, so types registered later by other packages count too.
    global _TYPES
    if name not in _TYPES:
        _TYPES = registered()
    return name in _TYPES


def schema_data(name: str) -> tuple[str, bytes]:
    """(encoding, data) of the MCAP schema for a type: its field order, so other tools can read the arrays.

    ``raw`` and ``liveliness`` have no schema data (empty encoding, as MCAP prescribes).
    """
    cls = registered().get(name)
    if cls is None:
        return "", b""
    doc = {
        "type": name,
        "wire": "msgpack array [TYPE, *fields]; numpy arrays as ext 1 (dtype code, ndim, u32 shape, raw LE bytes)",
        "fields": [[field, type(spec).__name__] for field, spec in cls.SPEC.items()],
    }
    return SCHEMA_ENCODING, json.dumps(doc, separators=(",", ":")).encode()


def world_of(key: str) -> str | None:
    """The world a recorded key belongs to (``rf/WORLD/...``), or None for a foreign key."""
    parts = key.split("/", 2)
    if len(parts) >= 2 and parts[0] == keys.PREFIX and parts[1]:
        return parts[1]
    return None


def remap_world(key: str, world: str) -> str:
    """``rf/OLD/rest`` -> ``rf/WORLD/rest``; keys outside ``rf/`` are left as they are."""
    parts = key.split("/", 2)
    if len(parts) < 2 or parts[0] != keys.PREFIX:
        return key
    rest = parts[2] if len(parts) == 3 else ""
    root = keys.world_root(world)
    return f"{root}/{rest}" if rest else root
