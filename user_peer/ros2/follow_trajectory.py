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

from user_peer.errors import FabricUserError
from user_peer.ros2.action_host import ActionHost
from user_peer.ros2.commands import CommandError
from user_peer.ros2.trajectory import TrajectoryPlayer, sample, timed_points

__all__ = [
    "GOAL_TIME_S",
    "GOAL_TOLERANCE_RAD",
    "FollowTrajectoryActions",
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
            start = arm.joints
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
        return self._watch(rid, handle, arm, names, playing, failed, goal_tol, path_tol, settle)

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
    ) -> Any:
        """Feedback every ``period`` until the goal ends (see the module's docstring for how)."""
        R, player, traj = self.action.Result, self.player, playing.traj
        feedback = self.action.Feedback(joint_names=names)
        wall_limit = time.monotonic() + 30.0 + 10.0 * (traj.duration + settle)  # a sim that stopped: not forever
        while True:
            now = player.clock() - playing.t0
            desired, over = sample(traj, playing.start, now)
            q, seen_at = _reading(arm, playing.t0, now)
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
            if q is not None:
                errors = [d - a for d, a in zip(desired, q)]
                self._feedback(feedback, playing, now, desired, q, errors)
                handle.publish_feedback(feedback)
                strayed = None if over else tolerance_miss(names, errors, path_tol)
                if strayed is not None:
                    player.stop(rid)
                    arm.stop(confirm=False)
                    return self._end(rid, handle, R.PATH_TOLERANCE_VIOLATED, f"{strayed} at {now:.2f} s")
                if over and current is None:
                    missed = tolerance_miss(names, errors, goal_tol)
                    if missed is None:
                        handle.succeed()
                        self.succeeded += 1
                        return R(error_code=R.SUCCESSFUL, error_string="")
                    # judged on a reading taken after the deadline: a starved bridge's clock (any robot's newest
                    # state) can run ahead of the arm's last reading (docs/testing.md: not the whole of run 12-13's miss)
                    if seen_at > traj.duration + settle or time.monotonic() > wall_limit:
                        return self._end(
                            rid,
                            handle,
                            R.GOAL_TOLERANCE_VIOLATED,
                            f"{missed}, {settle:.2f} s after the trajectory's end",
                        )
            if time.monotonic() > wall_limit:
                player.stop(rid)
                return self._end(
                    rid, handle, R.GOAL_TOLERANCE_VIOLATED, "the sim's clock stopped: the trajectory did not end"
                )
            time.sleep(self.period)

    def _feedback(
        self, fb: Any, playing: Any, now: float, desired: Sequence[float], q: Sequence[float], errors: Sequence[float]
    ) -> None:
        """``fb`` filled for ``now`` (s since the trajectory started): stamp in the sim's time, the point followed."""
        t = playing.t0 + now
        fb.header.stamp.sec, fb.header.stamp.nanosec = int(t), int(t % 1 * 1e9)
        fb.desired.positions, fb.actual.positions = [float(v) for v in desired], [float(v) for v in q]
        fb.error.positions = [float(v) for v in errors]
        for point in (fb.desired, fb.actual, fb.error):
            point.time_from_start.sec, point.time_from_start.nanosec = int(now), int(now % 1 * 1e9)
        fb.index = min(bisect.bisect_left(playing.traj.times, now), len(playing.traj.times) - 1)


def _reading(arm: Any, t0: float, now: float) -> tuple[Any, float]:
    """The arm's joints the bridge holds, and when (s since the trajectory started, by the sim's clock) they were
    read: one sample's positions and stamp together; ``now`` where the sample carries no stamp."""
    js = getattr(arm, "joint_state", None)
    if js is None:
        return arm.joints, now
    stamp = float(getattr(getattr(js, "header", None), "stamp", 0.0) or 0.0)
    return js.q, (stamp - t0 if stamp > 0 else now)
