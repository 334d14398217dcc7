"""What a ROS 2 arm command asks for: joint targets in the arm's order, or why it cannot be done.

``/ROBOT/joint_command`` carries a ``sensor_msgs/JointState`` (positions, by name in any order or in the arm's
order without names); ``/ROBOT/joint_trajectory`` a ``trajectory_msgs/JointTrajectory``, whose points the
bridge plays at their times (:mod:`user_peer.ros2.trajectory`, each point through :func:`joint_targets`;
:func:`trajectory_targets` gives where one ends). Two topics, because one ROS 2 topic carries one type (DDS refuses a second type on a topic
name in one participant).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

__all__ = ["CommandError", "joint_targets", "trajectory_targets"]


class CommandError(ValueError):
    """A command the bridge cannot turn into an arm target; its text says why (for /rosout)."""


def joint_targets(
    robot: str, arm_joints: Sequence[str], names: Sequence[str], positions: Sequence[float]
) -> list[float]:
    """``positions`` in the arm's joint order: by ``names`` when given (every joint named once, any order),
    else taken as already in the arm's order (their count checked)."""
    values = [float(v) for v in positions]
    joints = list(arm_joints)
    if names:
        if sorted(names) != sorted(joints) or len(values) != len(names):
            raise CommandError(f"names {list(names)} with {len(values)} positions are not {robot}'s joints {joints}")
        by_name = dict(zip(names, values))
        return [by_name[n] for n in joints]
    if len(values) != len(joints):
        raise CommandError(f"{len(values)} positions without names, {robot} has {len(joints)} joints {joints}")
    return values


def trajectory_targets(robot: str, arm_joints: Sequence[str], trajectory: Any) -> list[float]:
    """The last point of a ``trajectory_msgs/JointTrajectory`` (``joint_names``, ``points[].positions``) in the
    arm's joint order."""
    points = list(trajectory.points)
    if not points:
        raise CommandError("a JointTrajectory without points")
    return joint_targets(robot, arm_joints, list(trajectory.joint_names), list(points[-1].positions))
