"""``/NS/ARM/follow_joint_trajectory``: control_msgs' FollowJointTrajectory action for each arm the bridge drives.

What MoveIt's trajectory execution and ros2_control's clients send to a joint trajectory controller: a
``JointTrajectory`` with tolerances, feedback (desired, actual and error points, the point being followed) while
the arm moves, a result at the end. A goal takes the bridge's ``joint_trajectory`` path: its points checked by
:func:`~user_peer.ros2.trajectory.timed_points`, sent whole to the sim, which plays them at their
``time_from_start`` in its own time (the bridge's :class:`~user_peer.ros2.trajectory.TrajectoryPlayer` follows
them on /clock for feedback). As ros2_control's
controller does, it answers:

- ``INVALID_JOINTS`` (with ``error_string``) when ``joint_names`` are not the arm's joints, each once;
- ``INVALID_GOAL`` when the login may not command the arm (the reason, also on /rosout), when a point cannot be
  played (a time going back, a position outside the joint's limits), when the arm refused a target, or when a
  newer trajectory (another goal, or ``joint_trajectory``) replaced it;
- ``PATH_TOLERANCE_VIOLATED`` when a joint strays further than its ``path_tolerance`` from the desired point (then
  the arm is stopped); only tolerances given are checked, as the controller's defaults are none;
- ``SUCCESSFUL`` when, by the last point's time plus ``goal_time_tolerance`` (default :data:`GOAL_TIME_S`), every
  joint is within its ``goal_tolerance`` (default :data:`GOAL_TOLERANCE_RAD`; -1: not checked) of the last point,
  else ``GOAL_TOLERANCE_VIOLATED`` naming the joint and by how much.

Those times count, as a ROS controller's do, from when the controller (here the sim) began the trajectory, in its
own clock: an arm still when the goal came began it when it left where it stood (:func:`began_at`, from its
joint readings' stamps). The bridge's clock at the goal (the newest sim time it heard) is only a floor: a starved
bridge hears /clock late, and the goal reaches a loaded sim late (CI, 2026-12-02: 0.13 rad short "1.00 s after the
end" of a 3 s trajectory the arm then finished). An arm already moving is judged from the bridge's clock.

A cancel stops the trajectory and the arm where it is. ``multi_dof_trajectory`` is not followed (an arm has no
multi-DOF joints): a goal that has points in it is ``INVALID_JOINTS``.

``control_msgs`` is not among ROS 2 Kilted's wheels: :mod:`user_peer.ros2.msgbuild` builds it into the environment
(``make test`` does). Without it there is no action server and ``available`` is False (said at start). The servers
live on a node of their own, ``<bridge's node>_trajectory`` (:mod:`user_peer.ros2.action_host` says why).
"""

from __future__ import annotations

import bisect
import math
import time
from collections.abc import Sequence
from typing import Any, Callable

import numpy as np

from user_peer.errors import FabricUserError
from user_peer.ros2.action_host import ActionHost
from user_peer.ros2.commands import CommandError
from user_peer.ros2.trajectory import TrajectoryPlayer, sample, timed_points

__all__ = [
    "END_FEEDBACKS",
    "GOAL_TIME_S",
    "GOAL_TOLERANCE_RAD",
    "FollowTrajectoryActions",
    "began_at",
    "follow_action_class",
    "joint_names_error",
    "tolerances",
    "tolerance_miss",
]

GOAL_TOLERANCE_RAD = 0.01
"""A joint's distance from the last point (rad) within which a goal that gives no ``goal_tolerance`` succeeds."""
GOAL_TIME_S = 1.0
"""How long after the last point's time (s of the sim's clock) the arm may take to settle within its goal
tolerance when the goal gives no ``goal_time_tolerance``."""


def follow_action_class() -> type | None:
    """``control_msgs.action.FollowJointTrajectory`` where importable (built by :mod:`user_peer.ros2.msgbuild`)."""
    try:
        from control_msgs.action import FollowJointTrajectory
    except ImportError:
        return None
    return FollowJointTrajectory


def joint_names_error(robot: str, arm_joints: Sequence[str], names: Sequence[str]) -> str | None:
    """Why a goal's ``joint_names`` are not ``robot``'s joints (each once, any order); None when they are."""
    if len(set(names)) == len(names) and set(names) == set(arm_joints):
        return None
    unknown = [n for n in names if n not in arm_joints]
    lacking = [n for n in arm_joints if n not in names]
    parts = ([f"unknown {unknown}"] if unknown else []) + ([f"missing {lacking}"] if lacking else [])
    parts += [] if len(set(names)) == len(names) else ["a joint named twice"]
    return f"joint_names {list(names)} are not {robot}'s joints {list(arm_joints)}: {', '.join(parts)}"


def tolerances(arm_joints: Sequence[str], given: Sequence[Any], default: float) -> tuple[float, ...]:
    """Each joint's position tolerance from ``JointTolerance``s (by ``name``): 0 or not given -> ``default``,
    negative -> none (``math.inf``), as control_msgs defines them."""
    by_name = {t.name: float(t.position) for t in given}
    out = []
    for name in arm_joints:
        v = by_name.get(name, 0.0)
        out.append(default if v == 0.0 or not math.isfinite(v) else (math.inf if v < 0 else v))
    return tuple(out)


def tolerance_miss(arm_joints: Sequence[str], errors: Sequence[float], tol: Sequence[float]) -> str | None:
    """The first joint further than its tolerance (which, by how much), or None when all are within."""
    for name, e, t in zip(arm_joints, errors, tol):
        if abs(e) > t:
            return f"{name} is {abs(e):.4f} rad from where it should be (tolerance {t:.4f} rad)"
    return None


STILL_RAD_S = 1e-3
"""A joint slower than this (rad/s) is still (the sim's own threshold for an arm in motion)."""
END_FEEDBACKS = 3
"""Feedbacks sent at the end point, within the goal tolerance, before the result: rclpy's ActionClient drops
feedback that comes after its result, and a client (MoveIt's, a test's) is shown where the arm ended."""
MOVED_RAD = 1e-5
"""How far (rad) the arm must have left where it stood for the trajectory to have begun."""


def began_at(
    times: Sequence[float], positions: Sequence[Sequence[float]], q0: Sequence[float], q: Sequence[float], stamp: float
) -> float | None:
    """When (the sim's time) the trajectory ``times``/``positions`` began from ``q0``, where the arm stood still,
    given a reading ``q`` at ``stamp`` on the way: the reading's time less how far along the trajectory it is (its
    nearest point on the polyline from ``q0`` through the points, each segment walked linearly in its time, as the
    sim plays it). None while the arm has not left ``q0``, or where the trajectory does not move it."""
    q0a, qa = np.asarray(q0, dtype=float), np.asarray(q, dtype=float)
    if float(np.max(np.abs(qa - q0a), initial=0.0)) <= MOVED_RAD:
        return None
    best: tuple[float, float] | None = None  # (distance, elapsed)
    t_prev, p_prev = 0.0, q0a
    for t, p in zip(times, positions):
        pa = np.asarray(p, dtype=float)
        d = pa - p_prev
        dd = float(d @ d)
        if dd > 1e-18:
            frac = min(1.0, max(0.0, float((qa - p_prev) @ d) / dd))
            dist = float(np.linalg.norm(p_prev + frac * d - qa))
            if best is None or dist < best[0] - 1e-12:
                best = (dist, t_prev + frac * (float(t) - t_prev))
        t_prev, p_prev = float(t), pa
    return None if best is None else stamp - best[1]


def _seconds(d: Any) -> float:
    return float(d.sec) + float(d.nanosec) * 1e-9


class FollowTrajectoryActions(ActionHost):
    """One FollowJointTrajectory action server per driven arm, on a node of its own; goals played by ``player``."""

    def __init__(
        self,
        node: Any,
        namespace: str,
        player: TrajectoryPlayer,
        check_owner: Callable[..., Any],
        refuse: Callable[[str, str, str], None],
        *,
        period: float = 0.05,
    ) -> None:
        super().__init__(node, namespace, follow_action_class(), "follow_joint_trajectory", "trajectory")
        self.player, self.period = player, period
        self.check_owner, self.refuse = check_owner, refuse
        self.succeeded = 0

    def _end(self, rid: str, handle: Any, code: int, why: str, *, told: bool = True) -> Any:
        """Abort the goal with ``why`` (a refusal told on /rosout with ``told``)."""
        if told:
            self.refuse(rid, "follow_joint_trajectory", why)
        handle.abort()
        return self.action.Result(error_code=code, error_string=why)

    def _execute(self, rid: str, handle: Any) -> Any:
        R = self.action.Result
        why: list[str] = []
        arm = self.check_owner(rid, "follow_joint_trajectory", why.append)  # the bridge's: the refusal told on /rosout
        if arm is None:
            return self._end(
                rid, handle, R.INVALID_GOAL, why[0] if why else f"{rid}: this login may not command it", told=False
            )
        goal = handle.request
        names = list(arm.entry.joint_names)
        wrong = joint_names_error(rid, names, list(goal.trajectory.joint_names))
        if wrong is None and goal.multi_dof_trajectory.points:
            wrong = f"{rid} has no multi-DOF joints: multi_dof_trajectory must be empty"
        if wrong is not None:
            return self._end(rid, handle, R.INVALID_JOINTS, wrong)
        failed: list[str] = []
        try:
            timed = timed_points(rid, names, goal.trajectory, arm.entry.lower, arm.entry.upper)
            start, still = arm.joints, _still(arm)
            playing = self.player.play(
                rid,
                timed,
                None if start is None else list(start),
                lambda t: arm.follow_joints(t.times, t.positions, wait=False),
                lambda exc: failed.append(getattr(exc, "reason", str(exc))),
            )
        except (CommandError, FabricUserError, ValueError) as exc:
            return self._end(rid, handle, R.INVALID_GOAL, getattr(exc, "reason", str(exc)))
        if playing is None:
            return self._end(rid, handle, R.INVALID_GOAL, "the bridge is closing", told=False)
        goal_tol = tolerances(names, goal.goal_tolerance, GOAL_TOLERANCE_RAD)
        path_tol = tolerances(names, goal.path_tolerance, math.inf)
        settle = _seconds(goal.goal_time_tolerance) or GOAL_TIME_S
        return self._watch(rid, handle, arm, names, playing, failed, goal_tol, path_tol, settle, still)

    def _watch(
        self,
        rid: str,
        handle: Any,
        arm: Any,
        names: list[str],
        playing: Any,
        failed: list[str],
        goal_tol: tuple[float, ...],
        path_tol: tuple[float, ...],
        settle: float,
        still: tuple[tuple[float, ...], float] | None,
    ) -> Any:
        """Feedback every ``period`` until the goal ends (see the module's docstring for how); ``still``: where the
        arm stood still when the goal came and that reading's stamp (None: moving, or no stamped reading)."""
        R, player, traj = self.action.Result, self.player, playing.traj
        feedback = self.action.Feedback(joint_names=names)
        wall_limit = time.monotonic() + 30.0 + 10.0 * (traj.duration + settle)  # a sim that stopped: not forever
        t_start = playing.t0  # the bridge's clock at the goal, until the sim's own start is seen
        onset = still is not None and any(
            max(abs(a - b) for a, b in zip(p, still[0])) > MOVED_RAD for p in traj.positions
        )  # the start to be seen: the arm stood still, and the trajectory moves it
        at_end = 0  # feedbacks sent at the end point, within the goal's tolerance
        while True:
            now = player.clock() - t_start
            q, stamp = _reading(arm, t_start, now)
            if onset and still is not None and q is not None and stamp + t_start > still[1]:
                began = began_at(traj.times, traj.positions, still[0], q, stamp + t_start)
                if began is not None:
                    t_start, stamp, onset = began, stamp + t_start - began, False
            desired, over = sample(traj, playing.start, max(stamp, 0.0))
            if handle.is_cancel_requested:
                player.stop(rid)
                arm.stop(confirm=False)
                handle.canceled()
                return R(error_code=R.SUCCESSFUL, error_string="canceled: the arm stopped where it was")
            if failed:
                return self._end(rid, handle, R.INVALID_GOAL, f"the arm refused a target: {failed[0]}")
            current = player.current(rid)
            if current is not None and current is not playing:
                return self._end(rid, handle, R.INVALID_GOAL, "replaced by a newer trajectory for the arm", told=False)
            if q is not None and not onset:
                errors = [d - a for d, a in zip(desired, q)]
                self._feedback(feedback, playing, t_start, stamp, desired, q, errors)
                handle.publish_feedback(feedback)
                strayed = None if over else tolerance_miss(names, errors, path_tol)
                if strayed is not None:
                    player.stop(rid)
                    arm.stop(confirm=False)
                    return self._end(rid, handle, R.PATH_TOLERANCE_VIOLATED, f"{strayed} at {stamp:.2f} s")
                if over:  # judged on a reading the sim took after the trajectory's end, by its own clock
                    missed = tolerance_miss(names, errors, goal_tol)
                    at_end += missed is None
                    if at_end >= END_FEEDBACKS:
                        handle.succeed()
                        self.succeeded += 1
                        return R(error_code=R.SUCCESSFUL, error_string="")
                    if missed is not None and (stamp > traj.duration + settle or time.monotonic() > wall_limit):
                        return self._end(
                            rid,
                            handle,
                            R.GOAL_TOLERANCE_VIOLATED,
                            f"{missed}, {settle:.2f} s after the trajectory's end",
                        )
            if time.monotonic() > wall_limit:
                player.stop(rid)
                why = (
                    "the arm never left where it stood: the sim did not begin the trajectory"
                    if onset
                    else "the sim's clock stopped: the trajectory did not end"
                )
                return self._end(rid, handle, R.GOAL_TOLERANCE_VIOLATED, why)
            time.sleep(self.period)

    def _feedback(
        self,
        fb: Any,
        playing: Any,
        t_start: float,
        now: float,
        desired: Sequence[float],
        q: Sequence[float],
        errors: Sequence[float],
    ) -> None:
        """``fb`` filled for ``now`` (s since the sim began the trajectory at ``t_start``): stamp in the sim's time,
        the point followed."""
        t = t_start + now
        fb.header.stamp.sec, fb.header.stamp.nanosec = int(t), int(t % 1 * 1e9)
        fb.desired.positions, fb.actual.positions = [float(v) for v in desired], [float(v) for v in q]
        fb.error.positions = [float(v) for v in errors]
        for point in (fb.desired, fb.actual, fb.error):
            point.time_from_start.sec, point.time_from_start.nanosec = int(now), int(now % 1 * 1e9)
        fb.index = min(bisect.bisect_left(playing.traj.times, now), len(playing.traj.times) - 1)


def _stamp(js: Any) -> float:
    """A joint state's stamp (s of the sim's clock); 0 where it carries none."""
    return float(getattr(getattr(js, "header", None), "stamp", 0.0) or 0.0)


def _still(arm: Any) -> tuple[tuple[float, ...], float] | None:
    """Where the arm stands still and the stamp of that reading (one sample); None when it moves or has none."""
    js = getattr(arm, "joint_state", None)
    stamp = _stamp(js)
    if js is None or stamp <= 0 or float(np.max(np.abs(np.asarray(js.dq, dtype=float)), initial=0.0)) >= STILL_RAD_S:
        return None
    return tuple(float(v) for v in js.q), stamp


def _reading(arm: Any, t0: float, now: float) -> tuple[Any, float]:
    """The arm's joints the bridge holds, and when (s since the trajectory started, by the sim's clock) they were
    read: one sample's positions and stamp together; ``now`` where the sample carries no stamp."""
    js = getattr(arm, "joint_state", None)
    if js is None:
        return arm.joints, now
    stamp = _stamp(js)
    return js.q, (stamp - t0 if stamp > 0 else now)
