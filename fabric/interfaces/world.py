"""What a world holds: its robots, their sensors and scene objects (``rf/{world}/srv/world``), and the whole
world state a standby sim takes over (``rf/{world}/srv/state``).

:class:`WorldInfo` carries what other peers need to work with the world without a local copy of the
robot files: each robot's id, type, kind, spawn pose, joint names, limits and speeds, base limits and
sensors, and the scene objects. :class:`WorldState` is the whole state a standby needs to carry the robots on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from fabric.codec import Arr, F, I, Map, Msg, Msgs, Opt, S, Strs, Spec, register
from fabric.interfaces._arrays import frozen
from fabric.interfaces.ownership import OwnershipRecord
from fabric.interfaces.sensors import BaseInfo, LidarInfo, SonarInfo
from fabric.interfaces.std import MAX_PATH_POINTS, Header

__all__ = ["RobotInfo", "ObjectInfo", "WorldInfo", "RobotState", "WorldState"]


@dataclass(frozen=True, slots=True)
class RobotInfo:
    """One robot of a world. ``pose`` is its spawn pose (x, y, z, yaw); limits in rad, speeds in rad/s.

    ``base`` (mobile robots), ``lidar`` and ``sonar`` describe what it carries (:mod:`fabric.interfaces.sensors`);
    each is None when the robot has none.
    """

    id: str
    type: str
    kind: str
    pose: np.ndarray
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    max_speed: np.ndarray
    flange_site: str = ""
    flange_frame: str = ""
    base_radius: float = 0.0
    base: BaseInfo | None = None
    lidar: LidarInfo | None = None
    sonar: SonarInfo | None = None
    sim: str = ""
    """The sim peer that is the robot's authority (its ``srv/world`` part; "" in recordings from before shards)."""

    OPTIONAL_TAIL: ClassVar[int] = 1
    SPEC: ClassVar[Spec] = {
        "id": S(nonempty=True),
        "type": S(nonempty=True),
        "kind": S(choices=("arm", "mobile")),
        "pose": Arr(np.float64, shape=(4,)),
        "joint_names": Strs(),
        "lower": Arr(np.float64, ndim=1),
        "upper": Arr(np.float64, ndim=1),
        "max_speed": Arr(np.float64, ndim=1),
        "flange_site": S(),
        "flange_frame": S(),
        "base_radius": F(lo=0.0),
        "base": Opt(Msg(BaseInfo)),
        "lidar": Opt(Msg(LidarInfo)),
        "sonar": Opt(Msg(SonarInfo)),
        "sim": S(),
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        for name in ("pose", "lower", "upper", "max_speed"):
            object.__setattr__(self, name, frozen(getattr(self, name)))

    def check(self) -> None:
        n = len(self.joint_names)
        if not (self.lower.shape[0] == self.upper.shape[0] == self.max_speed.shape[0] == n):
            raise ValueError(f"RobotInfo {self.id}: {n} joints but limits/speeds of other lengths")
        for part in (self.lidar, self.sonar):
            if part is not None:
                part.check()


@dataclass(frozen=True, slots=True)
class ObjectInfo:
    """A scene object (mocap body) anyone may move: id, kind (ik_target, goal_pointer...), policy, current pose."""

    id: str
    kind: str
    policy: str
    position: np.ndarray
    quaternion: np.ndarray

    SPEC: ClassVar[Spec] = {
        "id": S(nonempty=True),
        "kind": S(),
        "policy": S(choices=("scene", "exclusive")),
        "position": Arr(np.float64, shape=(3,)),
        "quaternion": Arr(np.float64, shape=(4,)),
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", frozen(self.position))
        object.__setattr__(self, "quaternion", frozen(self.quaternion))


@dataclass(frozen=True, slots=True)
class WorldInfo:
    """The world a sim peer simulates: scene, timestep, stream rates (Hz), robots and scene objects."""

    world: str
    scene: str
    timestep: float
    rates: dict[str, float]
    robots: tuple[RobotInfo, ...]
    objects: tuple[ObjectInfo, ...] = ()
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "world": S(nonempty=True),
        "scene": S(),
        "timestep": F(lo=1e-6, hi=1.0),
        "rates": Map(),
        "robots": Msgs(RobotInfo),
        "objects": Msgs(ObjectInfo),
        "header": Msg(Header),
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "robots", tuple(self.robots))
        object.__setattr__(self, "objects", tuple(self.objects))

    def check(self) -> None:
        for r in self.robots:
            r.check()
        ids = [r.id for r in self.robots]
        if len(set(ids)) != len(ids):
            raise ValueError(f"WorldInfo robot ids repeat: {ids}")

    def robot(self, robot_id: str) -> RobotInfo:
        for r in self.robots:
            if r.id == robot_id:
                return r
        raise KeyError(f"no robot {robot_id!r} in world {self.world!r}")


# ---------------------------------------------------------------------- replicated authority


@dataclass(frozen=True, slots=True)
class RobotState:
    """One robot's controller state. Arm: ``q``/``dq``/``target`` are joints. Base: ``q`` is (x, y, yaw),
    ``dq`` (v, omega), ``target`` the commanded (v, omega), ``path`` the follower's (N, 2) points (empty:
    none). ``extra`` holds the scalars: speed scale, wheel angles, follower progress, counters."""

    id: str
    kind: str
    q: np.ndarray
    dq: np.ndarray
    target: np.ndarray
    path: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    extra: dict[str, Any] = field(default_factory=dict)

    SPEC: ClassVar[Spec] = {
        "id": S(nonempty=True),
        "kind": S(choices=("arm", "mobile")),
        "q": Arr(np.float64, ndim=1, max_elems=256),
        "dq": Arr(np.float64, ndim=1, max_elems=256),
        "target": Arr(np.float64, ndim=1, max_elems=256),
        "path": Arr(np.float64, ndim=2, max_elems=2 * MAX_PATH_POINTS),
        "extra": Map(),
    }

    def __post_init__(self) -> None:
        for name in ("q", "dq", "target"):
            object.__setattr__(self, name, frozen(getattr(self, name)))
        object.__setattr__(self, "path", frozen(np.asarray(self.path, dtype=np.float64).reshape(-1, 2)))


@dataclass(frozen=True, slots=True)
class WorldState:
    """Everything a standby needs to carry a world on: sim time, robots, objects, ownership, sequences.

    ``records`` carry ``lease_expiry`` as seconds *remaining* and ``users`` the ownership users' state
    (:func:`ownership.snapshot.export`); ``seqs`` the primary's next sequence number per key."""

    time: float
    steps: int
    robots: tuple[RobotState, ...]
    objects: tuple[ObjectInfo, ...]
    records: tuple[OwnershipRecord, ...] = ()
    users: dict[str, Any] = field(default_factory=dict)
    seqs: dict[str, int] = field(default_factory=dict)
    header: Header = field(default_factory=Header)

    SPEC: ClassVar[Spec] = {
        "time": F(lo=0.0),
        "steps": I(lo=0),
        "robots": Msgs(RobotState),
        "objects": Msgs(ObjectInfo),
        "records": Msgs(OwnershipRecord),
        "users": Map(max_items=4096),
        "seqs": Map(max_items=4096),
        "header": Msg(Header),
    }

    def robot(self, rid: str) -> RobotState | None:
        return next((r for r in self.robots if r.id == rid), None)


for _cls in (RobotInfo, ObjectInfo, WorldInfo, RobotState, WorldState):
    register(_cls)
