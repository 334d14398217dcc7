"""Ownership service messages: what a user asks the authority and what it answers.

Requests travel as query payloads on ``rf/{world}/own/{object}`` (fabric.keys.own);
a query there without payload is answered with the current OwnershipRecord.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from fabric.codec import I, Msg, S, User, register
from fabric.messages import Header, OwnershipRecord

__all__ = ["OwnRequest", "OwnReply"]

_HEADER = Msg(Header)


@dataclass(frozen=True, slots=True)
class OwnRequest:
    """``op`` is request|release|renew; ``wait`` asks to be queued when the robot moves."""

    op: str
    user: str
    wait: bool = False
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[dict] = {
        "op": S(choices=("request", "release", "renew")),
        "user": User(),
        "wait": I(lo=0, hi=1),
        "header": _HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "wait", bool(self.wait))


@dataclass(frozen=True, slots=True)
class OwnReply:
    """``outcome`` is granted|denied|queued|released|renewed; ``position`` counts from 1 when queued."""

    outcome: str
    reason: str
    position: int
    record: OwnershipRecord
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[dict] = {
        "outcome": S(choices=("granted", "denied", "queued", "released", "renewed")),
        "reason": S(),
        "position": I(lo=0),
        "record": Msg(OwnershipRecord),
        "header": _HEADER,
    }


register(OwnRequest)
register(OwnReply)
