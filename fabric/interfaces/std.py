"""The standard messages: the header every message carries and the streams robots and maps publish.

The room of :mod:`fabric.interfaces` that ROS splits into std_msgs, sensor_msgs and nav_msgs: a
:class:`Header`, joint states, poses, planar scans, paths and occupancy grids. Frozen dataclasses with
read-only arrays, each declaring its fields' shapes in ``SPEC`` (:mod:`fabric.codec`), which is what the
decoder validates against; ``check`` holds the rules that tie fields together. The caps (``MAX_*``) bound
what a client can make a peer hold.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from fabric.codec import Arr, F, I, Msg, S, Strs, Spec, register
from fabric.interfaces._arrays import frozen

__all__ = [
    "MAX_JOINTS",
    "MAX_RAYS",
    "MAX_PATH_POINTS",
    "MAX_GRID_CELLS",
    "Header",
    "JointState",
    "Pose",
    "Scan",
    "Path",
    "OccupancyGrid",
    "HEADER",
]

MAX_JOINTS = 256
MAX_RAYS = 8192
"""A scan cannot hold a million rays: 8192 is 20x the densest LIDAR a robot here carries."""
MAX_PATH_POINTS = 1 << 16
MAX_GRID_CELLS = 1 << 21
"""2 MiB of cells (a 72 m square at 5 cm): inside the sessions' 4 MiB message cap (fabric.config)."""


@dataclass(frozen=True, slots=True)
class Header:
    """Stamps every message: sim time (s), wall time (ns), per-stream sequence, source peer id, and
    ``term``: the term of the sim authority that wrote it (0 = no authority, e.g. a user).

    ``term`` is the fencing token of replicated authority: a standby that takes a world over raises
    it, and consumers ignore robot state and ownership records with a lower one
    (:mod:`fabric.fencing`). It is an optional trailing field: a header of term 0 has the wire form
    it had before terms existed, and old recordings decode with term 0."""

    stamp: float = 0.0
    wall_ns: int = 0
    seq: int = 0
    source: str = ""
    term: int = 0

    SPEC: ClassVar[Spec] = {"stamp": F(), "wall_ns": I(lo=0), "seq": I(lo=0), "source": S(), "term": I(lo=0)}
    OPTIONAL_TAIL: ClassVar[int] = 1

    @classmethod
    def now(cls, *, stamp: float = 0.0, seq: int = 0, source: str = "", term: int = 0) -> "Header":
        return cls(stamp=stamp, wall_ns=time.time_ns(), seq=seq, source=source, term=term)


register(Header, "Header")

HEADER = Msg(Header)
"""The field spec of a nested header, shared by every message class."""


def new_header() -> Header:
    return Header()


@dataclass(frozen=True, slots=True)
class JointState:
    names: tuple[str, ...]
    q: np.ndarray
    dq: np.ndarray
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "names": Strs(max_items=MAX_JOINTS),
        "q": Arr(np.float64, ndim=1, max_elems=MAX_JOINTS),
        "dq": Arr(np.float64, ndim=1, max_elems=MAX_JOINTS),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "q", frozen(self.q, np.float64))
        object.__setattr__(self, "dq", frozen(self.dq, np.float64))

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
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "position": Arr(np.float64, shape=(3,)),
        "quaternion": Arr(np.float64, shape=(4,)),
        "linear": Arr(np.float64, shape=(3,)),
        "angular": Arr(np.float64, shape=(3,)),
        "frame": S(),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        for name in ("position", "quaternion", "linear", "angular"):
            object.__setattr__(self, name, frozen(getattr(self, name), np.float64))

    def check(self) -> None:
        q = self.quaternion
        n = math.sqrt(float(q @ q))
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
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "angle_min": F(lo=-2 * math.pi, hi=2 * math.pi),
        "angle_increment": F(lo=-math.pi, hi=math.pi),
        "range_max": F(lo=0.0, hi=65.535),
        "ranges_mm": Arr(np.uint16, ndim=1, max_elems=MAX_RAYS),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "ranges_mm", frozen(self.ranges_mm, np.uint16))

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
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "x": Arr(np.float64, ndim=1, max_elems=MAX_PATH_POINTS),
        "y": Arr(np.float64, ndim=1, max_elems=MAX_PATH_POINTS),
        "theta": Arr(np.float64, ndim=1, max_elems=MAX_PATH_POINTS),
        "frame": S(),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        for name in ("x", "y", "theta"):
            object.__setattr__(self, name, frozen(getattr(self, name), np.float64))

    def check(self) -> None:
        if not (self.x.shape == self.y.shape == self.theta.shape):
            raise ValueError(
                f"Path arrays differ in length: x {self.x.shape}, y {self.y.shape}, theta {self.theta.shape}"
            )

    def __len__(self) -> int:
        return int(self.x.shape[0])


@dataclass(frozen=True, slots=True)
class OccupancyGrid:
    """Cells row-major (row = y), 0 free .. 100 occupied, 255 unknown; origin is (x, y, theta) of cell (0, 0)."""

    resolution: float
    origin: np.ndarray
    cells: np.ndarray
    header: Header = field(default_factory=new_header)

    UNKNOWN: ClassVar[int] = 255
    SPEC: ClassVar[Spec] = {
        "resolution": F(lo=1e-4, hi=100.0),
        "origin": Arr(np.float64, shape=(3,)),
        "cells": Arr(np.uint8, ndim=2, max_elems=MAX_GRID_CELLS),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", frozen(self.origin, np.float64))
        object.__setattr__(self, "cells", frozen(self.cells, np.uint8))

    def check(self) -> None:
        bad = (self.cells > 100) & (self.cells != 255)
        if bad.any():
            raise ValueError(f"OccupancyGrid cells must be 0..100 or 255, found {int(self.cells[bad][0])}")


for _cls in (JointState, Pose, Scan, Path, OccupancyGrid):
    register(_cls)
