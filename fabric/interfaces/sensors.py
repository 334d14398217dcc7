"""What a robot carries, described for other peers: its mobile base and its range sensors.

Parts of :class:`~fabric.interfaces.world.RobotInfo` (``base``, ``lidar``, ``sonar``, each absent when the
robot has none): typed fields, so the compute peer's mapping reads ``info.lidar.offset`` rather than a
string key it has to guess. Lengths in metres, angles in radians, in the robot frame (origin at the
midpoint of the wheel axle, x forward).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from fabric.codec import Arr, F, I, S, Spec, register
from fabric.interfaces._arrays import frozen

__all__ = ["BaseInfo", "LidarInfo", "SonarInfo"]

MAX_SONARS = 64


@dataclass(frozen=True, slots=True)
class BaseInfo:
    """A differential-drive base: footprint ``radius`` and ``height``, wheels, and its speed and acceleration limits
    (m/s, rad/s, m/s², rad/s²); ``reverse`` 1 when it may drive backwards along a path (plans for it may reverse)."""

    radius: float
    wheel_separation: float
    wheel_radius: float
    max_speed: float
    max_omega: float
    max_accel: float
    max_alpha: float
    height: float = 0.0
    reverse: int = 0

    OPTIONAL_TAIL: ClassVar[int] = 1  # reverse: added later
    SPEC: ClassVar[Spec] = {
        "radius": F(lo=0.0),
        "wheel_separation": F(lo=0.0),
        "wheel_radius": F(lo=0.0),
        "max_speed": F(lo=0.0),
        "max_omega": F(lo=0.0),
        "max_accel": F(lo=0.0),
        "max_alpha": F(lo=0.0),
        "height": F(lo=0.0),
        "reverse": I(lo=0, hi=1),
    }


@dataclass(frozen=True, slots=True)
class LidarInfo:
    """A planar LIDAR on site ``site``: ``rays`` rays from ``angle_min`` by ``angle_increment`` over ``fov``,
    ranges in [``range_min``, ``range_max``] with Gaussian ``noise_std``; ``offset`` (x, y, z) is where it sits
    in the robot frame (what a map needs to place a scan)."""

    site: str
    rays: int
    fov: float
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    noise_std: float = 0.0
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    SPEC: ClassVar[Spec] = {
        "site": S(),
        "rays": I(lo=1, hi=8192),
        "fov": F(lo=0.0, hi=2 * np.pi),
        "angle_min": F(lo=-2 * np.pi, hi=2 * np.pi),
        "angle_increment": F(lo=-np.pi, hi=np.pi),
        "range_min": F(lo=0.0),
        "range_max": F(lo=0.0),
        "noise_std": F(lo=0.0),
        "offset": Arr(np.float64, shape=(3,)),
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "offset", frozen(self.offset))

    def check(self) -> None:
        if self.range_max < self.range_min:
            raise ValueError(f"LidarInfo range_max {self.range_max} < range_min {self.range_min}")


@dataclass(frozen=True, slots=True)
class SonarInfo:
    """A ring of ultrasonic range sensors: one per angle in ``angles``, on a ring of ``radius`` around ``center``
    (x, y) at ``height``; ranges from the ring's rim in [``range_min``, ``range_max``]."""

    angles: np.ndarray
    radius: float
    height: float
    range_min: float
    range_max: float
    noise_std: float = 0.0
    center: np.ndarray = field(default_factory=lambda: np.zeros(2))

    SPEC: ClassVar[Spec] = {
        "angles": Arr(np.float64, ndim=1, max_elems=MAX_SONARS),
        "radius": F(lo=0.0),
        "height": F(),
        "range_min": F(lo=0.0),
        "range_max": F(lo=0.0),
        "noise_std": F(lo=0.0),
        "center": Arr(np.float64, shape=(2,)),
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "angles", frozen(np.asarray(self.angles, dtype=np.float64).reshape(-1)))
        object.__setattr__(self, "center", frozen(self.center))

    def check(self) -> None:
        if self.range_max < self.range_min:
            raise ValueError(f"SonarInfo range_max {self.range_max} < range_min {self.range_min}")


for _cls in (BaseInfo, LidarInfo, SonarInfo):
    register(_cls)
