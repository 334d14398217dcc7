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

__all__ = [
    "JointTarget",
    "JointTrajectory",
    "MAX_TRAJECTORY_POINTS",
    "Twist",
    "Stop",
    "Reset",
    "Command",
    "CommandBody",
    "COMMAND_BODIES",
    "sample_trajectory",
]

MAX_TRAJECTORY_POINTS = 4096
"""Points of one joint trajectory (MoveIt's plans have tens to hundreds; a 100 Hz recording of 40 s fits)."""


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
class JointTrajectory:
    """Timed joint positions the sim plays from the moment it takes the command: point ``i`` (``positions[i]``,
    rad or m) at ``times[i]`` s of the sim's time after it, reached from where the arm was (ROS's convention for a
    first point after 0 s), linearly between points, no joint faster than its limit.

    Why the sim plays it and not the sender: a sender starved for seconds (a bridge on a loaded machine) cannot keep
    a trajectory's timing target by target (a ROS trajectory's bridge sent nothing for 5 s of the sim's time, then
    its last point). ``times`` must not decrease and start at 0 or later."""

    times: np.ndarray
    positions: np.ndarray
    header: Header = field(default_factory=new_header)

    SPEC: ClassVar[Spec] = {
        "times": Arr(np.float64, ndim=1, max_elems=MAX_TRAJECTORY_POINTS),
        "positions": Arr(np.float64, ndim=2, max_elems=MAX_TRAJECTORY_POINTS * MAX_JOINTS),
        "header": HEADER,
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "times", frozen(self.times, np.float64))
        object.__setattr__(self, "positions", frozen(self.positions, np.float64))

    def check(self) -> None:
        n = self.times.shape[0]
        if n == 0 or self.positions.shape[0] != n:
            raise ValueError(
                f"JointTrajectory has {n} times and {self.positions.shape[0]} points (one each, at least 1)"
            )
        if not (np.isfinite(self.times).all() and np.isfinite(self.positions).all()):
            raise ValueError("JointTrajectory times and positions must be finite")
        if self.times[0] < 0 or (np.diff(self.times) < 0).any():
            raise ValueError(f"JointTrajectory times must start at 0 or later and not decrease: {self.times.tolist()}")

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def sample(self, start: np.ndarray | None, elapsed: float) -> tuple[np.ndarray, bool]:
        """Where the trajectory is ``elapsed`` s after it began, and whether it is over. Before the first point's
        time, between ``start`` (the joints when it began; None: the first point) and the first point."""
        return sample_trajectory(self.times, self.positions, start, elapsed)


def sample_trajectory(
    times: np.ndarray, positions: np.ndarray, start: np.ndarray | None, elapsed: float
) -> tuple[np.ndarray, bool]:
    """:meth:`JointTrajectory.sample` on bare arrays (the ROS bridge's player samples the same way for feedback)."""
    times = np.asarray(times, dtype=np.float64)
    positions = np.asarray(positions, dtype=np.float64)
    if start is not None:
        times = np.concatenate(([0.0], times))
        positions = np.vstack((np.asarray(start, dtype=np.float64)[None, :], positions))
    if elapsed >= times[-1]:
        return positions[-1].copy(), True
    i = int(np.searchsorted(times, elapsed, side="right"))
    if i == 0:
        return positions[0].copy(), False
    t0, t1 = float(times[i - 1]), float(times[i])
    a = 0.0 if t1 <= t0 else (elapsed - t0) / (t1 - t0)
    return positions[i - 1] + a * (positions[i] - positions[i - 1]), False


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


CommandBody = Union[JointTarget, JointTrajectory, Twist, Path, Stop, Reset]


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
        "body": Msg(JointTarget, JointTrajectory, Twist, Path, Stop, Reset),
        "header": HEADER,
    }


for _cls in (JointTarget, JointTrajectory, Twist, Stop, Reset, Command):
    register(_cls)

COMMAND_BODIES: dict[str, type] = {
    "joints": JointTarget,
    "trajectory": JointTrajectory,
    "twist": Twist,
    "path": Path,
    "stop": Stop,
    "reset": Reset,
}
"""Which body each ``cmd/{name}`` key carries."""
