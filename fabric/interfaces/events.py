"""Events: what peers tell the world on ``rf/{world}/event/**`` (a refused command, an ownership change,
a clamp, a warning), and the error replies of services; :class:`EventKind` names every kind sent.

An event's ``kind`` is a plain string on the wire (a third-party peer may send kinds of its own), but
every kind robofabric sends is a member of :class:`EventKind`, and code that sends or matches one
names the member, so a sender and a listener cannot drift apart on spelling.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, ClassVar

from fabric.codec import Map, S, Spec, register
from fabric.interfaces.std import HEADER, Header, new_header
from fabric.limits import MAX_USER_LEN

__all__ = ["Event", "EventKind", "REJECT_KINDS"]


class EventKind(enum.StrEnum):
    """Every event kind robofabric sends; a member is its string (``EventKind.REJECT == "reject"``)."""

    # any peer (fabric.session)
    DECODE_ERROR = "decode_error"
    """A payload that did not decode (on ``event/decode/{peer}``)."""
    SERVICE_ERROR = "service_error"
    """A service's refusal: the payload of an error reply, not published."""
    # the sim (sim_peer.serving.peer), on event/{kind}/{robot}
    REJECT = "reject"
    """A command the sim refused; ``reason``: not_owner, stale_epoch, unknown_robot, user_mismatch, wrong_body, ..."""
    CLAMP = "clamp"
    """A command applied after clamping to the robot's limits (``reason``: out_of_range, over_limit)."""
    PATH_DONE = "path_done"
    TWIST_TIMEOUT = "twist_timeout"
    """No fresh twist within the sim's deadman (``--twist-timeout``): the base brakes to a halt."""
    OWNER_STOP = "owner_stop"
    """A moving robot lost its owner (released, handed over, taken over, her lease ended, she left) and
    stopped: a base brakes within its limits, an arm holds where it is; ``reason`` says how, ``user`` names her."""
    COLLISION = "collision"
    """The bumper stopped a base before an obstacle."""
    OBSTACLE_STOP = "obstacle_stop"
    """A base following a path and what its LIDAR sees in its way (sim_peer.physics.way_guard): ``reason`` waiting (it
    stopped short of it), resumed (the way cleared), blocked (it stayed closed: the path is dropped, plan again)."""
    MOVE_REFUSED = "move_refused"
    """A sim refused a step of a move (on ``event/move``): asked on a key every login may ask, no robot handed
    out in that move, a type not installed here...; ``reason`` says which, ``user`` names the login asking."""
    # the compute peer, on event/ik_unreachable/{robot}
    IK_UNREACHABLE = "ik_unreachable"
    # the ownership authority, on event/own/{object}
    OWN_REFUSED = "own_refused"
    OWN_HANDOVER = "own_handover"
    OWN_REVOKED = "own_revoked"
    OWN_EXPIRED = "own_expired"
    OWN_RESTORED = "own_restored"
    OWN_RELEASED = "own_released"
    OWN_STAFF = "own_staff"
    """An instructor's action on an object (ownership.staff: taken back, given, locked, unlocked, stopped, reset);
    ``reason`` says what it did, ``user`` names the instructor."""

    @classmethod
    def ownership(cls, effect: str) -> "EventKind":
        """The event kind of an ownership change (``handover`` -> ``own_handover``); ValueError for other effects."""
        return cls(f"own_{effect}")


REJECT_KINDS: frozenset[str] = frozenset({EventKind.REJECT})
"""Kinds with which a sim refuses a user's command (the reason says why)."""


@dataclass(frozen=True, slots=True)
class Event:
    """Something worth telling: a rejected command, an ownership change, a clamp, a warning."""

    kind: str
    reason: str = ""
    object: str = ""
    user: str = ""
    severity: str = "info"
    data: dict[str, Any] = field(default_factory=dict)
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "kind": S(nonempty=True),
        "reason": S(),
        "object": S(),
        "user": S(max_len=MAX_USER_LEN),
        "severity": S(choices=("debug", "info", "warning", "error")),
        "data": Map(),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", str(self.kind))  # an EventKind member travels as its plain string


register(Event)
