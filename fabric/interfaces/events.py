"""Events: what peers tell the world on ``rf/{world}/event/**`` (a refused command, an ownership change,
a clamp, a warning), and the error replies of services.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from fabric.codec import Map, S, register
from fabric.interfaces.std import HEADER, Header, _header
from fabric.limits import MAX_USER_LEN

__all__ = ["Event"]


@dataclass(frozen=True, slots=True)
class Event:
    """Something worth telling: a rejected command, an ownership change, a clamp, a warning."""

    kind: str
    reason: str = ""
    object: str = ""
    user: str = ""
    severity: str = "info"
    data: dict = field(default_factory=dict)
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {
        "kind": S(nonempty=True),
        "reason": S(),
        "object": S(),
        "user": S(max_len=MAX_USER_LEN),
        "severity": S(choices=("debug", "info", "warning", "error")),
        "data": Map(),
        "header": HEADER,
    }


register(Event)
