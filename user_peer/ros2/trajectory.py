"""A ``trajectory_msgs/JointTrajectory`` followed in time: its points at their ``time_from_start``.

The fabric's arm command is a joint target that the sim's controller reaches at the arm's joint speed
(``Arm.move_joints``); it has no timed waypoints. So the bridge plays a trajectory itself: from the arm's joints
when it arrives (ROS's convention: a first point after 0 s is reached from where the arm is), it sends the
trajectory's position, interpolated linearly between its points, every ``PERIOD_S`` of the bridge's clock
until the last point's time, then the last point. A target 20 ms ahead is one the controller reaches within the
tick, so the arm follows the points at their times (as long as they ask for no more than its joint speed: the
sim clamps a faster one, and the arm arrives late). A new trajectory for the arm replaces the one it plays, as
a ROS joint trajectory controller does. Timing is the clock the player is given: the bridge gives it the sim's
time (what /clock carries), as a ROS controller with ``use_sim_time`` follows /clock, so a sim slower than the
wall clock (a loaded machine) or paused stretches the trajectory instead of cutting its corners; the thread wakes
every ``PERIOD_S`` of wall clock to send the target for the sim's now.

Pure parts (:func:`timed_points`, :func:`sample`) apart from the player's thread (:class:`TrajectoryPlayer`).
"""

from __future__ import annotations

import bisect
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from user_peer.ros2.commands import CommandError, joint_targets

__all__ = ["PERIOD_S", "Timed", "TrajectoryPlayer", "sample", "timed_points"]

PERIOD_S = 0.02
"""s between two targets sent while a trajectory plays (50 Hz, the rate of the sim's arm controller's inputs)."""


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
    """Where the trajectory is ``elapsed`` s after its start, and whether it is over. Before the first point's time,
    between ``start`` (the arm's joints at the start; None: the first point) and the first point."""
    times = ((0.0,) + traj.times) if start is not None else traj.times
    positions = ((tuple(start),) + traj.positions) if start is not None else traj.positions
    if elapsed >= times[-1]:
        return positions[-1], True
    i = bisect.bisect_right(times, elapsed)
    if i == 0:
        return positions[0], False
    t0, t1 = times[i - 1], times[i]
    a = 0.0 if t1 <= t0 else (elapsed - t0) / (t1 - t0)
    return tuple(p + a * (q - p) for p, q in zip(positions[i - 1], positions[i])), False


@dataclass(slots=True)
class _Playing:
    traj: Timed
    start: tuple[float, ...] | None
    t0: float
    send: Callable[[tuple[float, ...]], None]
    failed: Callable[[Exception], None]


class TrajectoryPlayer:
    """Plays one trajectory per arm on a thread of its own (started with the first trajectory); ``close()`` ends it.

    ``send(q)`` is the arm's command (``move_joints(q, wait=False)``); an exception from it ends that trajectory
    and goes to ``failed`` (the bridge's refusal on /rosout)."""

    def __init__(
        self, clock: Callable[[], float] = time.monotonic, period: float = PERIOD_S, *, thread: bool = True
    ) -> None:
        self.clock, self.period = clock, period
        self._threaded = thread  # False: the caller calls step() (tests, with a fake clock)
        self._playing: dict[str, _Playing] = {}
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closed = False
        self._thread: threading.Thread | None = None

    def play(
        self,
        robot: str,
        traj: Timed,
        start: Sequence[float] | None,
        send: Callable[[tuple[float, ...]], None],
        failed: Callable[[Exception], None],
    ) -> _Playing | None:
        """Follow ``traj`` on ``robot`` from now, replacing what it plays; what plays (None once closed), which
        :meth:`current` returns until it is over, failed, stopped or replaced."""
        with self._lock:
            if self._closed:
                return None
            p = self._playing[robot] = _Playing(
                traj, None if start is None else tuple(float(v) for v in start), self.clock(), send, failed
            )
            if self._thread is None and self._threaded:
                self._thread = threading.Thread(target=self._run, name="ros2-trajectories", daemon=True)
                self._thread.start()
        self._wake.set()
        return p

    def current(self, robot: str) -> _Playing | None:
        """What ``robot`` plays now (the FollowJointTrajectory action watches its goal's with it)."""
        with self._lock:
            return self._playing.get(robot)

    def stop(self, robot: str) -> None:
        """Stop what ``robot`` plays (a joint_command took over)."""
        with self._lock:
            self._playing.pop(robot, None)

    def playing(self) -> set[str]:
        with self._lock:
            return set(self._playing)

    def step(self) -> None:
        """Send each playing arm its target for now; drop the trajectories that are over or failed."""
        with self._lock:
            items = list(self._playing.items())
        now = self.clock()
        for robot, p in items:
            q, done = sample(p.traj, p.start, now - p.t0)
            try:
                p.send(q)
            except Exception as exc:  # the arm's refusal: told once, the trajectory dropped
                done = True
                p.failed(exc)
            if done:
                with self._lock:
                    if self._playing.get(robot) is p:
                        del self._playing[robot]

    def _run(self) -> None:
        while not self._closed:
            if not self.playing():
                self._wake.wait(1.0)
                self._wake.clear()
                continue
            self.step()
            time.sleep(self.period)

    def close(self) -> None:
        self._closed = True
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
