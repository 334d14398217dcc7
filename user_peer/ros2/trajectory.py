"""A ``trajectory_msgs/JointTrajectory`` followed in time: its points at their ``time_from_start``.

The bridge sends a trajectory whole, as the fabric's ``trajectory`` arm command
(:class:`~fabric.interfaces.JointTrajectory`, :meth:`user_peer.arm.Arm.follow_joints`): the sim plays it in its own
time, from the arm's joints when it takes it (ROS's convention: a first point after 0 s is reached from where the
arm is), linearly between its points, as a ROS controller with ``use_sim_time`` follows /clock. So a sim slower
than the wall clock (a loaded machine) or paused stretches the trajectory instead of cutting its corners, and a
bridge starved for seconds changes nothing of it. (Until the eighth session, 2026-12-01, the bridge played it target
by target: at load 25 it sent nothing for 5 s of the sim's time, then the last point.) A new trajectory for the arm
replaces the one it plays, as a ROS joint trajectory controller does; a point faster than the arm's joint speed
is reached late (the sim moves no joint faster than its limit).

:class:`TrajectoryPlayer` keeps what each arm plays, in the bridge's clock (the sim's time, from /clock), so that
the FollowJointTrajectory action can give the desired point as feedback and know when it is over.

Pure parts (:func:`timed_points`, :func:`sample`) apart from the player (:class:`TrajectoryPlayer`, on a clock
passed in).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fabric.interfaces import sample_trajectory
from user_peer.ros2.commands import CommandError, joint_targets

__all__ = ["Timed", "TrajectoryPlayer", "sample", "timed_points"]


@dataclass(frozen=True, slots=True)
class Timed:
    """A trajectory's points in the arm's joint order, with their times from its start (s, non-decreasing)."""

    times: tuple[float, ...]
    positions: tuple[tuple[float, ...], ...]

    @property
    def duration(self) -> float:
        return self.times[-1]


def timed_points(
    robot: str, arm_joints: Sequence[str], trajectory: Any, lower: Sequence[float] = (), upper: Sequence[float] = ()
) -> Timed:
    """A JointTrajectory's points (``joint_names`` in any order) as :class:`Timed`; :class:`CommandError` for no
    points, a time that goes back or is not finite, a position that is not finite or outside [lower, upper]."""
    points = list(trajectory.points)
    if not points:
        raise CommandError("a JointTrajectory without points")
    names = list(trajectory.joint_names)
    times, positions = [], []
    for i, p in enumerate(points):
        t = float(p.time_from_start.sec) + float(p.time_from_start.nanosec) * 1e-9
        q = joint_targets(robot, arm_joints, names, list(p.positions))
        if not math.isfinite(t) or t < 0 or (times and t < times[-1]):
            raise CommandError(f"point {i}'s time_from_start {t:.3f} s goes back (times must not decrease)")
        if not all(math.isfinite(v) for v in q):
            raise CommandError(f"point {i} has a position that is not finite: {q}")
        for j, v in enumerate(q):
            if len(lower) == len(q) and not lower[j] - 1e-9 <= v <= upper[j] + 1e-9:
                raise CommandError(
                    f"point {i}: {arm_joints[j]} at {math.degrees(v):.1f} deg is outside its limits "
                    f"[{math.degrees(lower[j]):.1f}, {math.degrees(upper[j]):.1f}] deg"
                )
        times.append(t)
        positions.append(tuple(q))
    return Timed(tuple(times), tuple(positions))


def sample(traj: Timed, start: Sequence[float] | None, elapsed: float) -> tuple[tuple[float, ...], bool]:
    """Where the trajectory is ``elapsed`` s after its start, and whether it is over: the sim's own sampling
    (:func:`fabric.interfaces.sample_trajectory`), so the action's desired point is the one the sim aims at.
    Before the first point's time, between ``start`` (the arm's joints at the start; None: the first point) and
    the first point."""
    q, over = sample_trajectory(
        np.asarray(traj.times, dtype=float),
        np.asarray(traj.positions, dtype=float),
        None if start is None else np.asarray(start, dtype=float),
        elapsed,
    )
    return tuple(float(v) for v in q), over


@dataclass(slots=True)
class _Playing:
    traj: Timed
    start: tuple[float, ...] | None
    t0: float
    send: Callable[[Timed], None]
    failed: Callable[[Exception], None]


class TrajectoryPlayer:
    """What each arm plays: a trajectory is sent whole to the arm's sim (``send(traj)``: its ``trajectory``
    command) and is the arm's :meth:`current` one until it is over on ``clock``, stopped or replaced. An exception
    from ``send`` ends it at once and goes to ``failed`` (the bridge's refusal on /rosout)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self._playing: dict[str, _Playing] = {}
        self._lock = threading.Lock()
        self._closed = False

    def play(
        self,
        robot: str,
        traj: Timed,
        start: Sequence[float] | None,
        send: Callable[[Timed], None],
        failed: Callable[[Exception], None],
    ) -> _Playing | None:
        """Send ``traj`` to ``robot`` now, replacing what it plays; what plays (None once closed), which
        :meth:`current` returns until it is over, failed, stopped or replaced."""
        with self._lock:
            if self._closed:
                return None
            p = self._playing[robot] = _Playing(
                traj, None if start is None else tuple(float(v) for v in start), self.clock(), send, failed
            )
        try:
            send(traj)
        except Exception as exc:  # the arm's refusal: told, the trajectory dropped
            with self._lock:
                if self._playing.get(robot) is p:
                    del self._playing[robot]
            failed(exc)
        return p

    def current(self, robot: str) -> _Playing | None:
        """What ``robot`` plays now (the FollowJointTrajectory action watches its goal's with it)."""
        self._drop_over()
        with self._lock:
            return self._playing.get(robot)

    def stop(self, robot: str) -> None:
        """Forget what ``robot`` plays (a joint_command took over: the sim's joint target replaced the trajectory)."""
        with self._lock:
            self._playing.pop(robot, None)

    def playing(self) -> set[str]:
        self._drop_over()
        with self._lock:
            return set(self._playing)

    def _drop_over(self) -> None:
        now = self.clock()
        with self._lock:
            for robot in [r for r, p in self._playing.items() if now - p.t0 >= p.traj.duration]:
                del self._playing[robot]

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._playing.clear()
