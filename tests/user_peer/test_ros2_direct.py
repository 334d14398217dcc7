"""The bridge's direct builders (user_peer.ros2.direct) give the messages the export's conversion gives: for any
joint state, scan, sonar ring and pose, a reused rclpy message refilled in place equals one filled from
``ros2_message``'s dict, field by field (values, frames, stamps, +inf for a missing echo, the sonar's offset)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rclpy  # noqa: E402,F401  (the test extra installs ROS 2 Kilted's wheels: missing, these tests fail)

from fabric.interfaces import Header, JointState, Pose, Scan  # noqa: E402
from fabric.interfaces.geometry import quaternion_from_yaw  # noqa: E402
from user_peer.openfmt.ros2 import ros2_message  # noqa: E402
from user_peer.ros2 import direct  # noqa: E402
from user_peer.ros2.fill import fill, message_class  # noqa: E402

floats = st.floats(-50.0, 50.0, allow_nan=False)
stamps = st.integers(1, 2**62)


def exported(key: str, msg, ns: int, **kw):
    type_name, fields = ros2_message(key, msg, ns, **kw)
    return fill(message_class(type_name)(), fields)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.text("abcxyz_", min_size=1, max_size=6), floats, floats), max_size=8, unique_by=lambda t: t[0]
    ),
    stamps,
    stamps,
)
def test_a_joint_state_built_in_place_is_the_exports(joints, ns, ns2):
    from sensor_msgs.msg import JointState as RosJointState

    js = JointState(tuple(j[0] for j in joints), np.array([j[1] for j in joints]), np.array([j[2] for j in joints]))
    out = RosJointState()
    direct.joint_state(out, "base", JointState(("old",), np.ones(1), np.ones(1)), ns2)  # a previous sample, overwritten
    assert direct.joint_state(out, "arm1/base_link", js, ns) == exported("rf/w/robot/arm1/joints", js, ns)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.integers(0, 65535), max_size=300),
    st.floats(-3.0, 3.0),
    st.floats(-0.1, 0.1),
    st.floats(0.5, 65.0),
    st.floats(0.0, 0.5),
    st.sampled_from(["scan", "sonar"]),
    stamps,
    st.sampled_from([0.0, 0.05, 0.1]),
)
def test_a_scan_built_in_place_is_the_exports(mm, angle_min, inc, range_max, range_min, leaf, ns, scan_time):
    from sensor_msgs.msg import LaserScan

    scan = Scan(angle_min, inc, range_max, np.array(mm, dtype=np.uint16))
    offset = 0.26 if leaf == "sonar" else 0.0
    mine = direct.laser_scan(
        LaserScan(), f"base1/{'sonar' if leaf == 'sonar' else 'laser'}", scan, ns, range_min, offset, scan_time
    )
    theirs = exported(
        f"rf/w/robot/base1/{leaf}", scan, ns, range_min=range_min, range_offset=offset, scan_time=scan_time
    )
    assert mine == theirs and mine.scan_time == pytest.approx(scan_time) and mine.time_increment == 0.0
    assert all(math.isinf(r) for r, m in zip(mine.ranges, scan.ranges) if m >= range_max - 5e-4)


@settings(max_examples=60, deadline=None)
@given(floats, floats, st.floats(-math.pi, math.pi), floats, floats, floats, stamps)
def test_a_pose_built_in_place_is_the_exports_odometry_or_pose(x, y, yaw, vx, vy, wz, ns):
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Odometry

    pose = Pose(
        np.array([x, y, 0.0]),
        quaternion_from_yaw(yaw),
        np.array([vx, vy, 0.0]),
        np.array([0.0, 0.0, wz]),
        header=Header(stamp=1.0),
    )
    odom = direct.odometry(Odometry(), "base1", pose, ns)
    assert odom == exported("rf/w/robot/base1/pose", pose, ns, kind="mobile")
    # a floor of (1 mm)^2 on the diagonal, never all zero (read as "not set"), symmetric, the same for the twist
    cov = np.asarray(odom.pose.covariance).reshape(6, 6)
    assert np.array_equal(cov, np.diag(np.full(6, 1e-6))) and np.array_equal(
        odom.twist.covariance, odom.pose.covariance
    )
    assert direct.pose_stamped(PoseStamped(), pose, ns) == exported("rf/w/robot/arm1/pose", pose, ns, kind="arm")


def test_the_scan_time_is_one_over_the_worlds_scan_rate_and_unknown_without_it():
    from fabric.interfaces import WorldInfo
    from user_peer.openfmt.ros2 import scan_period

    assert scan_period(WorldInfo("w", "s", 0.002, {"scan": 20.0, "joints": 100.0}, ())) == pytest.approx(0.05)
    assert scan_period(WorldInfo("w", "s", 0.002, {"joints": 100.0}, ())) == 0.0
    assert scan_period(WorldInfo("w", "s", 0.002, {"scan": 0.0}, ())) == 0.0
    assert scan_period(None) == 0.0
