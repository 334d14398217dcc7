"""Commands a robot's owner sends on ``rf/{world}/robot/{id}/cmd/{name}``, and their envelope.

Every command travels in a :class:`Command` naming the user and the ownership epoch it was sent under
(the fencing token the authority checks); :data:`COMMAND_BODIES` says which body each ``cmd/{name}``
key carries.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Union

import numpy as np

from fabric.codec import Arr, F, I, Msg, User, Spec, register
from fabric.interfaces._arrays import frozen
from fabric.interfaces.std import HEADER, MAX_JOINTS, Header, Path, new_header

__all__ = ["JointTarget", "Twist", "Stop", "Reset", "Command", "CommandBody", "COMMAND_BODIES"]


@dataclass(frozen=True, slots=True)
class JointTarget:
    """Joint position targets (rad or m); ``speed_scale`` in (0, 1] scales the robot's speed limits."""

    q: np.ndarray
    speed_scale: float = 1.0
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "q": Arr(np.float64, ndim=1, max_elems=MAX_JOINTS),
        "speed_scale": F(lo=1e-6, hi=1.0),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", frozen(self.q, np.float64))


@dataclass(frozen=True, slots=True)
class Twist:
    """Planar base velocity: forward speed v (m/s) and yaw rate omega (rad/s)."""

    v: float
    omega: float
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {"v": F(), "omega": F(), "header": HEADER}


@dataclass(frozen=True, slots=True)
class Stop:
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {"header": HEADER}


@dataclass(frozen=True, slots=True)
class Reset:
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {"header": HEADER}


CommandBody = Union[JointTarget, Twist, Path, Stop, Reset]


@dataclass(frozen=True, slots=True)
class Command:
    """A command envelope: who sends it and under which ownership epoch (the fencing token)."""

    user: str
    epoch: int
    body: CommandBody
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "user": User(),
        "epoch": I(lo=0),
        "body": Msg(JointTarget, Twist, Path, Stop, Reset),
        "header": HEADER,
    }


for _cls in (JointTarget, Twist, Stop, Reset, Command):
    register(_cls)

COMMAND_BODIES: dict[str, type] = {
    "joints": JointTarget,
    "twist": Twist,
    "path": Path,
    "stop": Stop,
    "reset": Reset,
}
"""Which body each ``cmd/{name}`` key carries."""
