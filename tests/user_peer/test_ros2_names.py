"""Frame ids under ``--namespace`` (user_peer.ros2.names): every frame a namespaced bridge sends carries the
namespace's prefix (the root ``map`` too), in the messages built in place, in those filled from the export's
dicts (a Path's poses included), in /tf's transforms, and a goal is taken in the prefixed fixed frame; without a
namespace nothing changes."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry

from fabric.interfaces import Header, Path, Pose
from fabric.interfaces.geometry import quaternion_from_yaw
from user_peer.openfmt.frames import Frame
from user_peer.openfmt.ros2 import ros2_message
from user_peer.ros2 import direct
from user_peer.ros2.commands import CommandError
from user_peer.ros2.fill import fill, message_class
from user_peer.ros2.goals import goal_of
from user_peer.ros2.names import frame_prefix, prefix_headers
from user_peer.ros2.tf import transform


def test_a_namespace_is_a_frame_prefix_and_none_is_nothing():
    assert frame_prefix("class1") == frame_prefix("/class1/") == "class1/"
    assert frame_prefix("") == frame_prefix("/") == ""


def test_odometry_poses_paths_and_transforms_carry_the_prefix():
    pose = Pose(np.array([1.0, 2.0, 0.0]), quaternion_from_yaw(0.5), header=Header(stamp=1.0))
    odom = direct.odometry(Odometry(), "base1", pose, 7, "class1/")
    assert (odom.header.frame_id, odom.child_frame_id) == ("class1/base1/odom", "class1/base1/base_link")
    plain = direct.odometry(Odometry(), "base1", pose, 7)
    assert (plain.header.frame_id, plain.child_frame_id) == ("base1/odom", "base1/base_link")
    assert direct.pose_stamped(PoseStamped(), pose, 7, "class1/").header.frame_id == "class1/map"
    path = Path(np.array([0.0, 1.0]), np.array([0.0, 1.0]), np.array([0.0, 0.0]))
    type_name, fields = ros2_message("rf/w/robot/base1/path", path, 7)
    msg = prefix_headers(fill(message_class(type_name)(), fields), "class1/")
    assert msg.header.frame_id == "class1/map" and {p.header.frame_id for p in msg.poses} == {"class1/map"}
    t = transform(Frame("base1/base_link", "base1/laser", (0.1, 0.0, 0.2), (0.0, 0.0, 0.0, 1.0)), 7, "class1/")
    assert (t.header.frame_id, t.child_frame_id) == ("class1/base1/base_link", "class1/base1/laser")


@pytest.mark.parametrize(
    "frame,prefix,ok",
    [
        ("world", "", True),
        ("map", "", True),
        ("", "", True),
        ("class1/world", "", False),
        ("class1/world", "class1/", True),
        ("class1/map", "class1/", True),
        ("world", "class1/", True),
        ("class2/world", "class1/", False),
        ("class1/base1", "class1/", False),
        ("class1/", "class1/", False),
    ],
)
def test_a_goal_is_taken_in_the_namespaces_fixed_frame(frame, prefix, ok):
    g = PoseStamped()
    g.header.frame_id, g.pose.position.x, g.pose.orientation.w = frame, 1.5, 1.0
    if ok:
        assert goal_of(g, prefix)[0] == 1.5
    else:
        with pytest.raises(CommandError, match="bridge's fixed frame"):
            goal_of(g, prefix)
