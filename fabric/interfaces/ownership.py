"""Ownership: the replicated record of who owns an object, and what a user asks its authority.

The authority (the sim that simulates the object) is the only writer of ``rf/{world}/own/{object}``
(an :class:`OwnershipRecord`); a user's :class:`OwnRequest` travels as a query payload on
``rf/{world}/own/{object}/by/{user}`` and is answered with an :class:`OwnReply`. A query on
``own/{object}`` without payload is answered with the current record.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from fabric.codec import F, I, Msg, S, Strs, User, Spec, register
from fabric.interfaces.std import HEADER, Header, new_header
from fabric.limits import MAX_USER_LEN

__all__ = ["MAX_QUEUE", "OwnershipRecord", "OwnRequest", "OwnReply", "STAFF_OPS"]

MAX_QUEUE = 64
"""Users waiting for one object (ownership.state refuses the 65th)."""
STAFF_OPS = ("take_back", "give", "lock", "unlock", "stop", "reset")
"""An instructor's actions on one object (:mod:`ownership.staff`), asked on ``own/{object}/staff/by/{login}``,
which a class's router opens to the instructor logins alone: take it back from its owner (the next in the
queue gets it), give it to a logged-in user, lock it (nobody may request it) and unlock it, stop it, reset it."""


@dataclass(frozen=True, slots=True)
class OwnershipRecord:
    """Replicated ownership state of one object, written only by its authority.

    ``owner`` is empty when the object is free; ``lease_expiry`` is in the
    authority's clock (seconds) and meaningful to the authority alone: a renewal is answered
    with the record, not published (published records change with owner, epoch, queue or
    motion); ``queue`` holds waiting users in join order.
    """

    object: str
    policy: str = "exclusive"
    owner: str = ""
    epoch: int = 0
    lease_expiry: float = 0.0
    queue: tuple[str, ...] = ()
    state: str = "still"
    authority: str = ""
    header: Header = field(default_factory=new_header)
    locked: str = ""
    """The instructor who locked the object (:data:`STAFF_OPS` ``lock``): nobody may request it until it is
    unlocked; empty when it is not locked."""

    SPEC: ClassVar[Spec] = {
        "object": S(nonempty=True),
        "policy": S(choices=("scene", "exclusive")),
        "owner": S(max_len=MAX_USER_LEN),
        "epoch": I(lo=0),
        "lease_expiry": F(),
        "queue": Strs(max_items=MAX_QUEUE, max_len=MAX_USER_LEN),
        "state": S(choices=("still", "moving")),
        "authority": S(),
        "header": HEADER,
        "locked": S(max_len=MAX_USER_LEN),
    }
    OPTIONAL_TAIL: ClassVar[int] = 1  # locked: added later, left off the wire when empty

    def __post_init__(self) -> None:
        object.__setattr__(self, "queue", tuple(self.queue))


@dataclass(frozen=True, slots=True)
class OwnRequest:
    """``op`` is request|release|renew on the user's own key, or one of :data:`STAFF_OPS` on the staff's key
    (``own/{object}/staff/by/{login}``); ``wait`` asks to be queued when the robot moves; ``to``: whom a
    ``give`` hands the object to."""

    op: str
    user: str
    wait: bool = False
    header: Header = field(default_factory=Header)
    to: str = ""

    SPEC: ClassVar[Spec] = {
        "op": S(choices=("request", "release", "renew", *STAFF_OPS)),
        "user": User(),
        "wait": I(lo=0, hi=1),
        "header": HEADER,
        "to": S(max_len=MAX_USER_LEN),
    }
    OPTIONAL_TAIL: ClassVar[int] = 1  # to: added later, left off the wire when empty

    def __post_init__(self) -> None:
        object.__setattr__(self, "wait", bool(self.wait))


@dataclass(frozen=True, slots=True)
class OwnReply:
    """``outcome`` is granted|denied|queued|released|renewed (``done``: a staff action carried out); ``position``
    counts from 1 when queued."""

    outcome: str
    reason: str
    position: int
    record: OwnershipRecord
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "outcome": S(choices=("granted", "denied", "queued", "released", "renewed", "done")),
        "reason": S(),
        "position": I(lo=0),
        "record": Msg(OwnershipRecord),
        "header": HEADER,
    }


for _cls in (OwnershipRecord, OwnRequest, OwnReply):
    register(_cls)
