"""An arm command from ROS 2 becomes targets in the arm's joint order, or a refusal that says why: a JointState's
positions by name in any order (or in the arm's order without names), a JointTrajectory's last point; names that
are not the arm's, a count that does not match, a trajectory without points are refused with their reason."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from user_peer.ros2.commands import CommandError, joint_targets, trajectory_targets

ARM = ("joint_1", "joint_2", "joint_3")


@given(st.permutations(range(3)), st.lists(st.floats(-3, 3), min_size=3, max_size=3))
def test_positions_by_name_in_any_order_come_out_in_the_arms_order(order, values):
    names = [ARM[i] for i in order]
    got = joint_targets("arm1", ARM, names, [values[i] for i in order])
    assert got == [float(v) for v in values]


def test_without_names_the_positions_are_the_arms_order_and_their_count_is_checked():
    assert joint_targets("arm1", ARM, [], [0.1, 0.2, 0.3]) == [0.1, 0.2, 0.3]
    with pytest.raises(CommandError, match="2 positions without names, arm1 has 3 joints"):
        joint_targets("arm1", ARM, [], [0.1, 0.2])


@pytest.mark.parametrize(
    "names, positions",
    [
        (["joint_1", "joint_2", "elbow"], [0, 0, 0]),
        (["joint_1", "joint_2"], [0, 0]),
        (["joint_1", "joint_2", "joint_3"], [0, 0]),
    ],
)
def test_names_that_are_not_the_arms_joints_or_a_short_list_are_refused(names, positions):
    with pytest.raises(CommandError, match="are not arm1's joints"):
        joint_targets("arm1", ARM, names, positions)


def test_a_trajectory_gives_its_last_point_and_one_without_points_is_refused():
    import rclpy  # noqa: F401  (the test extra installs ROS 2 Kilted's wheels: missing, this fails)
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    t = JointTrajectory()
    t.joint_names = ["joint_3", "joint_1", "joint_2"]
    for positions in ([1.0, 2.0, 3.0], [0.3, 0.1, 0.2]):
        p = JointTrajectoryPoint()
        p.positions = positions
        t.points.append(p)
    assert trajectory_targets("arm1", ARM, t) == [0.1, 0.2, 0.3]
    with pytest.raises(CommandError, match="without points"):
        trajectory_targets("arm1", ARM, JointTrajectory())
