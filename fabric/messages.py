"""Typed messages of the fabric.

Frozen dataclasses, one per kind of data that crosses a key. Arrays are numpy
arrays made read-only on construction, so a message really is a value: a
subscriber can hand it to another thread without copying. Each class declares
the shape of its fields in ``SPEC`` (see :mod:`fabric.codec`), which is what the
decoder validates against; ``check`` holds the rules that tie fields together.

Other packages may add message types with :func:`fabric.codec.register`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar, Union

import numpy as np

from fabric.codec import Arr, F, I, S, Strs, Msg, Map, User, register
from fabric.limits import MAX_USER_LEN

MAX_JOINTS = 256
MAX_RAYS = 8192
"""A scan cannot hold a million rays: 8192 is 20x the densest LIDAR a robot here carries."""
MAX_PATH_POINTS = 1 << 16
MAX_GRID_CELLS = 1 << 21
"""2 MiB of cells (a 72 m square at 5 cm): inside the sessions' 4 MiB message cap (fabric.config)."""
MAX_QUEUE = 64
"""Users waiting for one object (ownership.state refuses the 65th)."""


def _ro(a: Any, dtype: Any) -> np.ndarray:
    arr = np.array(a, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, slots=True)
class Header:
    """Stamps every message: sim time (s), wall time (ns), per-stream sequence, source peer id, and
    ``term``: the authority epoch of the sim that wrote it (issue 16; 0 = no authority, e.g. a user).

    ``term`` is the fencing token of replicated authority: a standby that takes a world over raises
    it, and consumers ignore robot state and ownership records with a lower one
    (:mod:`fabric.fencing`). It is an optional trailing field: a header of term 0 has the wire form
    it had before terms existed, and old recordings decode with term 0."""

    stamp: float = 0.0
    wall_ns: int = 0
    seq: int = 0
    source: str = ""
    term: int = 0

    SPEC: ClassVar[dict] = {"stamp": F(), "wall_ns": I(lo=0), "seq": I(lo=0), "source": S(), "term": I(lo=0)}
    OPTIONAL_TAIL: ClassVar[int] = 1

    @classmethod
    def now(cls, *, stamp: float = 0.0, seq: int = 0, source: str = "", term: int = 0) -> "Header":
        return cls(stamp=stamp, wall_ns=time.time_ns(), seq=seq, source=source, term=term)


register(Header, "Header")

_HEADER = Msg(Header)


def _header() -> Header:
    return Header()


@dataclass(frozen=True, slots=True)
class JointState:
    names: tuple[str, ...]
    q: np.ndarray
    dq: np.ndarray
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {
        "names": Strs(max_items=MAX_JOINTS),
        "q": Arr(np.float64, ndim=1, max_elems=MAX_JOINTS),
        "dq": Arr(np.float64, ndim=1, max_elems=MAX_JOINTS),
        "header": _HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "q", _ro(self.q, np.float64))
        object.__setattr__(self, "dq", _ro(self.dq, np.float64))

    def check(self) -> None:
        if not (len(self.names) == self.q.shape[0] == self.dq.shape[0]):
            raise ValueError(
                f"JointState has {len(self.names)} names, {self.q.shape[0]} positions and {self.dq.shape[0]} velocities"
            )


@dataclass(frozen=True, slots=True)
class Pose:
    """Position (m), orientation quaternion (w, x, y, z), linear and angular velocity in ``frame``."""

    position: np.ndarray
    quaternion: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    linear: np.ndarray = field(default_factory=lambda: np.zeros(3))
    angular: np.ndarray = field(default_factory=lambda: np.zeros(3))
    frame: str = "world"
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {
        "position": Arr(np.float64, shape=(3,)),
        "quaternion": Arr(np.float64, shape=(4,)),
        "linear": Arr(np.float64, shape=(3,)),
        "angular": Arr(np.float64, shape=(3,)),
        "frame": S(),
        "header": _HEADER,
    }

    def __post_init__(self) -> None:
        for name in ("position", "quaternion", "linear", "angular"):
            object.__setattr__(self, name, _ro(getattr(self, name), np.float64))

    def check(self) -> None:
        n = float(np.linalg.norm(self.quaternion))
        if not (0.99 < n < 1.01):
            raise ValueError(f"Pose quaternion must have unit norm, got norm {n:.4f}")


@dataclass(frozen=True, slots=True)
class Scan:
    """A planar range scan. Ranges travel as uint16 millimetres; ``ranges`` gives metres.

    A ray that hit nothing reads ``range_max``.
    """

    angle_min: float
    angle_increment: float
    range_max: float
    ranges_mm: np.ndarray
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {
        "angle_min": F(lo=-2 * math.pi, hi=2 * math.pi),
        "angle_increment": F(lo=-math.pi, hi=math.pi),
        "range_max": F(lo=0.0, hi=65.535),
        "ranges_mm": Arr(np.uint16, ndim=1, max_elems=MAX_RAYS),
        "header": _HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "ranges_mm", _ro(self.ranges_mm, np.uint16))

    @classmethod
    def from_ranges(
        cls, ranges_m: Any, *, angle_min: float, angle_increment: float, range_max: float, header: Header | None = None
    ) -> "Scan":
        """Quantise metres to millimetres; misses (inf, NaN, negative) and long ranges read ``range_max``."""
        r = np.asarray(ranges_m, dtype=np.float64)
        r = np.where(np.isfinite(r) & (r >= 0), np.minimum(r, range_max), range_max)
        mm = np.rint(r * 1000.0).astype(np.uint16)
        return cls(angle_min, angle_increment, range_max, mm, header or Header())

    @property
    def ranges(self) -> np.ndarray:
        return self.ranges_mm.astype(np.float64) / 1000.0

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(self.ranges_mm.shape[0])


@dataclass(frozen=True, slots=True)
class Path:
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    frame: str = "world"
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {
        "x": Arr(np.float64, ndim=1, max_elems=MAX_PATH_POINTS),
        "y": Arr(np.float64, ndim=1, max_elems=MAX_PATH_POINTS),
        "theta": Arr(np.float64, ndim=1, max_elems=MAX_PATH_POINTS),
        "frame": S(),
        "header": _HEADER,
    }

    def __post_init__(self) -> None:
        for name in ("x", "y", "theta"):
            object.__setattr__(self, name, _ro(getattr(self, name), np.float64))

    def check(self) -> None:
        if not (self.x.shape == self.y.shape == self.theta.shape):
            raise ValueError(f"Path arrays differ in length: x {self.x.shape}, y {self.y.shape}, theta {self.theta.shape}")

    def __len__(self) -> int:
        return int(self.x.shape[0])


@dataclass(frozen=True, slots=True)
class OccupancyGrid:
    """Cells row-major (row = y), 0 free .. 100 occupied, 255 unknown; origin is (x, y, theta) of cell (0, 0)."""

    resolution: float
    origin: np.ndarray
    cells: np.ndarray
    header: Header = field(default_factory=_header)

    UNKNOWN: ClassVar[int] = 255
    SPEC: ClassVar[dict] = {
        "resolution": F(lo=1e-4, hi=100.0),
        "origin": Arr(np.float64, shape=(3,)),
        "cells": Arr(np.uint8, ndim=2, max_elems=MAX_GRID_CELLS),
        "header": _HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _ro(self.origin, np.float64))
        object.__setattr__(self, "cells", _ro(self.cells, np.uint8))

    def check(self) -> None:
        bad = (self.cells > 100) & (self.cells != 255)
        if bad.any():
            raise ValueError(f"OccupancyGrid cells must be 0..100 or 255, found {int(self.cells[bad][0])}")


@dataclass(frozen=True, slots=True)
class JointTarget:
    """Joint position targets (rad or m); ``speed_scale`` in (0, 1] scales the robot's speed limits."""

    q: np.ndarray
    speed_scale: float = 1.0
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {"q": Arr(np.float64, ndim=1, max_elems=MAX_JOINTS), "speed_scale": F(lo=1e-6, hi=1.0), "header": _HEADER}

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", _ro(self.q, np.float64))


@dataclass(frozen=True, slots=True)
class Twist:
    """Planar base velocity: forward speed v (m/s) and yaw rate omega (rad/s)."""

    v: float
    omega: float
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {"v": F(), "omega": F(), "header": _HEADER}


@dataclass(frozen=True, slots=True)
class Stop:
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {"header": _HEADER}


@dataclass(frozen=True, slots=True)
class Reset:
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {"header": _HEADER}


CommandBody = Union[JointTarget, Twist, Path, Stop, Reset]


@dataclass(frozen=True, slots=True)
class Command:
    """A command envelope: who sends it and under which ownership epoch (the fencing token)."""

    user: str
    epoch: int
    body: CommandBody
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {
        "user": User(),
        "epoch": I(lo=0),
        "body": Msg(JointTarget, Twist, Path, Stop, Reset),
        "header": _HEADER,
    }


@dataclass(frozen=True, slots=True)
class OwnershipRecord:
    """Replicated ownership state of one object, written only by its authority.

    ``owner`` is empty when the object is free; ``lease_expiry`` is in the
    authority's clock (seconds); ``queue`` holds waiting users in join order.
    """

    object: str
    policy: str = "exclusive"
    owner: str = ""
    epoch: int = 0
    lease_expiry: float = 0.0
    queue: tuple[str, ...] = ()
    state: str = "still"
    authority: str = ""
    header: Header = field(default_factory=_header)

    SPEC: ClassVar[dict] = {
        "object": S(nonempty=True),
        "policy": S(choices=("scene", "exclusive")),
        "owner": S(max_len=MAX_USER_LEN),
        "epoch": I(lo=0),
        "lease_expiry": F(),
        "queue": Strs(max_items=MAX_QUEUE, max_len=MAX_USER_LEN),
        "state": S(choices=("still", "moving")),
        "authority": S(),
        "header": _HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "queue", tuple(self.queue))


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
        "header": _HEADER,
    }


for _cls in (JointState, Pose, Scan, Path, OccupancyGrid, JointTarget, Twist, Stop, Reset, Command, OwnershipRecord, Event):
    register(_cls)

COMMAND_BODIES: dict[str, type] = {
    "joints": JointTarget,
    "twist": Twist,
    "path": Path,
    "stop": Stop,
    "reset": Reset,
}
"""Which body each ``cmd/{name}`` key carries."""
