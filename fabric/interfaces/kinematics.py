"""Request and reply messages of the kinematics services, and the streamed IK solution.

``rf/{world}/srv/ik/{robot}`` takes an :class:`IKRequest`, ``srv/fk/{robot}`` an
:class:`FKRequest` and ``srv/jacobian/{robot}`` a :class:`JacobianRequest`; in
streaming mode the compute peer publishes :class:`IKStream` on
``rf/{world}/robot/{robot}/ik``. Positions are in the world frame unless
``frame`` says ``base`` (the arm's own base frame), because users think in the
world the viewer shows, while the arm's base sits wherever the scene put it.
Quaternions are (w, x, y, z) like every fabric message. Optional arrays are
empty when absent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Sequence

import numpy as np

from fabric.codec import Arr, F, I, S, Spec, register
from fabric.interfaces._arrays import frozen, vector
from fabric.interfaces.std import HEADER, Header

__all__ = [
    "FRAMES",
    "IK_METHODS",
    "IKRequest",
    "IKReply",
    "FKRequest",
    "FKReply",
    "JacobianRequest",
    "JacobianReply",
    "IKStream",
]

FRAMES = ("world", "base")
IK_METHODS = ("auto", "closed_form", "numerical", "casadi")


def _check_len(owner: str, name: str, arr: np.ndarray, allowed: tuple[int, ...]) -> None:
    if arr.shape[0] not in allowed:
        want = " or ".join(str(n) for n in allowed)
        raise ValueError(f"{owner}.{name} must have {want} values, got {arr.shape[0]}")


@dataclass(frozen=True, slots=True)
class IKRequest:
    """Joint angles putting the flange at ``position`` (m) and, if given, ``quaternion``.

    ``seed``: the joints to stay near (empty: the robot's latest published joints, else zeros).
    ``method``: auto (closed form where the robot has one), closed_form, numerical (LM) or casadi (IPOPT, hard limits).
    """

    position: np.ndarray
    quaternion: np.ndarray = field(default_factory=lambda: np.zeros(0))
    seed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    frame: str = "world"
    method: str = "auto"
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "position": Arr(np.float64, shape=(3,)),
        "quaternion": Arr(np.float64, ndim=1),
        "seed": Arr(np.float64, ndim=1),
        "frame": S(choices=FRAMES),
        "method": S(choices=IK_METHODS),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", vector(self.position))
        object.__setattr__(self, "quaternion", vector(self.quaternion))
        object.__setattr__(self, "seed", vector(self.seed))

    def check(self) -> None:
        _check_len("IKRequest", "position", self.position, (3,))
        _check_len("IKRequest", "quaternion", self.quaternion, (0, 4))
        if self.quaternion.shape[0] == 4 and float(np.linalg.norm(self.quaternion)) < 1e-6:
            raise ValueError("IKRequest.quaternion has zero norm")
        if self.seed.shape[0] > 64:
            raise ValueError(f"IKRequest.seed has {self.seed.shape[0]} values; no robot has that many joints")

    @classmethod
    def make(
        cls,
        position: Sequence[float],
        quaternion: Sequence[float] | None = None,
        seed: Sequence[float] | None = None,
        **kw: Any,
    ) -> "IKRequest":
        """Build from plain sequences (None for absent), as the user API holds them."""
        return cls(vector(position), vector(quaternion), vector(seed), **kw)


@dataclass(frozen=True, slots=True)
class IKReply:
    """The chosen joints, how they were found, the residual errors and the solve time on the server."""

    robot: str
    q: np.ndarray
    solver: str
    position_error: float
    orientation_error: float
    candidates: int
    solve_us: float
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "robot": S(),
        "q": Arr(np.float64, ndim=1),
        "solver": S(),
        "position_error": F(lo=0.0),
        "orientation_error": F(lo=0.0),
        "candidates": I(lo=0),
        "solve_us": F(lo=0.0),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", vector(self.q))


@dataclass(frozen=True, slots=True)
class FKRequest:
    """Flange pose for joints ``q`` in ``frame``."""

    q: np.ndarray
    frame: str = "world"
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {"q": Arr(np.float64, ndim=1), "frame": S(choices=FRAMES), "header": HEADER}

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", vector(self.q))


@dataclass(frozen=True, slots=True)
class FKReply:
    """Flange position (m) and quaternion (w, x, y, z) in ``frame``."""

    robot: str
    position: np.ndarray
    quaternion: np.ndarray
    frame: str
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "robot": S(),
        "position": Arr(np.float64, shape=(3,)),
        "quaternion": Arr(np.float64, shape=(4,)),
        "frame": S(choices=FRAMES),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", vector(self.position))
        object.__setattr__(self, "quaternion", vector(self.quaternion))


@dataclass(frozen=True, slots=True)
class JacobianRequest:
    """The geometric Jacobian at ``q``; with joint rates ``dq`` also the flange twist and Eq. 7 speeds."""

    q: np.ndarray
    dq: np.ndarray = field(default_factory=lambda: np.zeros(0))
    frame: str = "world"
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "q": Arr(np.float64, ndim=1),
        "dq": Arr(np.float64, ndim=1),
        "frame": S(choices=FRAMES),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", vector(self.q))
        object.__setattr__(self, "dq", vector(self.dq))

    def check(self) -> None:
        if self.dq.shape[0] not in (0, self.q.shape[0]):
            raise ValueError(f"JacobianRequest.dq has {self.dq.shape[0]} values for {self.q.shape[0]} joints")


@dataclass(frozen=True, slots=True)
class JacobianReply:
    """``jacobian`` 6xN (linear rows first) in ``frame``; ``twist`` (6,) and ``speeds`` (N,) when dq was given."""

    robot: str
    jacobian: np.ndarray
    twist: np.ndarray
    speeds: np.ndarray
    frame: str
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "robot": S(),
        "jacobian": Arr(np.float64, ndim=2),
        "twist": Arr(np.float64, ndim=1),
        "speeds": Arr(np.float64, ndim=1),
        "frame": S(choices=FRAMES),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "jacobian", frozen(self.jacobian))
        object.__setattr__(self, "twist", vector(self.twist))
        object.__setattr__(self, "speeds", vector(self.speeds))


@dataclass(frozen=True, slots=True)
class IKStream:
    """One streamed IK solution (the paper's Test A): joints for the target's latest pose.

    ``target``: the object followed and its position (world frame). ``ok`` False with ``reason`` when
    the target is unreachable (``q`` is then empty). ``dq``: the joint rates of a synchronised move from
    the robot's current joints at its speed limits; ``speeds``: their Eq. 7 magnitudes; ``seconds``: the
    move's duration. The user decides whether to apply ``q`` (send it on ``cmd/joints``).
    """

    robot: str
    target: str
    position: np.ndarray
    ok: bool
    reason: str
    q: np.ndarray
    dq: np.ndarray
    speeds: np.ndarray
    seconds: float
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "robot": S(),
        "target": S(),
        "position": Arr(np.float64, shape=(3,)),
        "ok": I(lo=0, hi=1),
        "reason": S(),
        "q": Arr(np.float64, ndim=1),
        "dq": Arr(np.float64, ndim=1),
        "speeds": Arr(np.float64, ndim=1),
        "seconds": F(lo=0.0),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "ok", bool(self.ok))
        for name in ("position", "q", "dq", "speeds"):
            object.__setattr__(self, name, vector(getattr(self, name)))


for _cls in (IKRequest, IKReply, FKRequest, FKReply, JacobianRequest, JacobianReply, IKStream):
    register(_cls)
