"""The ROS 2 bridge's pieces without a world: the export's conversion filled into real rclpy messages, a base's
odometry twist in its own frame, and the one-line error when rclpy is missing."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from robofabric.cli import main
from fabric.interfaces import Header, JointState, OccupancyGrid, Path, Pose, Scan
from fabric.interfaces.geometry import quaternion_from_yaw
from user_peer.openfmt.ros2 import ros2_message

STAMP = 1_764_000_000_123_456_789


def needs_rclpy() -> None:
    import rclpy  # noqa: F401  (the test extra installs ROS 2 Kilted's wheels: missing, this fails)


def ros(key: str, msg, **kw) -> object:
    from user_peer.ros2.fill import fill, message_class

    type_name, fields = ros2_message(key, msg, STAMP, **kw)
    return fill(message_class(type_name)(), fields)


def test_the_exports_conversion_fills_live_messages_with_the_same_frames_stamps_and_values():
    needs_rclpy()
    js = ros("rf/w/robot/arm1/joints", JointState(("j1", "j2"), np.array([0.25, -1.5]), np.array([0.0, 0.1])))
    assert type(js).__name__ == "JointState" and js.header.frame_id == "arm1/base_link"
    assert (js.header.stamp.sec, js.header.stamp.nanosec) == (1_764_000_000, 123_456_789)
    assert list(js.name) == ["j1", "j2"] and list(js.position) == [0.25, -1.5] and list(js.velocity) == [0.0, 0.1]
    scan = Scan(-1.0, 0.5, 8.0, np.array([1000, 2500, 8000], dtype=np.uint16))
    ls = ros("rf/w/robot/base1/scan", scan, range_min=0.05)
    assert ls.header.frame_id == "base1/laser" and ls.range_max == 8.0 and ls.angle_max == pytest.approx(0.0)
    assert ls.range_min == pytest.approx(0.05)  # the sensor's, which the caller reads from the world description
    assert [float(r) for r in ls.ranges] == [1.0, 2.5, np.inf]  # no echo (range_max in the fabric): +inf, REP 117
    sonar = ros(
        "rf/w/robot/base1/sonar",
        Scan(0.0, 0.5, 3.0, np.array([400, 3000], dtype=np.uint16)),
        range_min=0.02,
        range_offset=0.26,
    )  # measured from a rim of radius 0.26: true from the centre
    assert sonar.header.frame_id == "base1/sonar" and sonar.range_min == pytest.approx(0.28)
    assert sonar.range_max == pytest.approx(3.26) and list(sonar.ranges) == pytest.approx([0.66, np.inf])
    path = ros("rf/w/robot/base1/path", Path(np.array([0.0, 1.0]), np.array([0.0, 2.0]), np.array([0.0, np.pi / 2])))
    assert len(path.poses) == 2 and path.poses[1].header.frame_id == "map"
    assert (path.poses[1].pose.position.x, path.poses[1].pose.position.y) == (1.0, 2.0)
    assert path.poses[1].pose.orientation.z == pytest.approx(np.sqrt(0.5))
    cells = np.array([[0, 100, 255]], dtype=np.uint8)
    grid = ros("rf/w/map/map", OccupancyGrid(0.1, np.array([1.0, 2.0, 0.0]), cells))
    assert list(grid.data) == [0, 100, -1] and (grid.info.width, grid.info.height) == (3, 1)
    assert grid.info.origin.position.x == 1.0 and grid.header.frame_id == "map"


def test_a_bases_odometry_gives_its_twist_in_its_own_frame():
    needs_rclpy()
    from nav_msgs.msg import Odometry

    from user_peer.ros2 import direct

    yaw = np.pi / 2  # facing +y, driving forward at 0.4 m/s: the sim's world velocity is (0, 0.4)
    pose = Pose(
        np.array([1.0, 2.0, 0.0]),
        quaternion_from_yaw(yaw),
        np.array([0.0, 0.4, 0.0]),
        np.array([0.0, 0.0, 0.3]),
        header=Header(wall_ns=STAMP),
    )
    odom = direct.odometry(Odometry(), "base1", pose, STAMP)
    assert odom == ros("rf/w/robot/base1/pose", pose, kind="mobile")  # the export's Odometry, live
    assert (odom.header.frame_id, odom.child_frame_id) == ("base1/odom", "base1/base_link")
    assert (odom.pose.pose.position.x, odom.pose.pose.position.y) == (1.0, 2.0)
    assert odom.twist.twist.linear.x == pytest.approx(0.4) and odom.twist.twist.linear.y == pytest.approx(
        0.0, abs=1e-12
    )
    assert odom.twist.twist.angular.z == pytest.approx(0.3)


def test_without_rclpy_the_command_says_which_extra_to_install(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "rclpy", None)  # what `import rclpy` meets where neither the extra nor ROS is
    assert main(["ros2", "--world", "w", "--connect", "tcp/127.0.0.1:9"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "robofabric[ros2]" in err[0] and "source a ROS 2 install" in err[0], err


def test_the_export_gives_a_sonar_ring_its_ranges_from_the_centre_and_its_sensors_range_min(tmp_path):
    """``export --to ros2`` of a recording without a world description: the ring's radius comes from the robot's
    own description (reeman: 0.26 m), so ranges measured from the rim are true in ``base1/sonar`` at its centre."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from user_peer.openfmt.ros2 import Ros2Writer

    h = Header(0.1, STAMP, 1, "sim")
    with Ros2Writer(tmp_path / "s.mcap") as w:
        w.write("rf/w/robot/base1/pose", Pose(np.zeros(3), header=h), STAMP)  # base1 is a reeman base
        w.write("rf/w/robot/base1/sonar", Scan(0.0, 0.5, 3.0, np.array([400, 3000], dtype=np.uint16), header=h), STAMP)
    factory = DecoderFactory()
    got = None
    with open(tmp_path / "s.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.topic.endswith("/sonar"):
                got = factory.decoder_for(channel.message_encoding, schema)(message.data)
    assert got is not None and got.header.frame_id == "base1/sonar"
    assert list(got.ranges) == pytest.approx([0.66, np.inf]) and got.range_max == pytest.approx(3.26)
    assert got.range_min == pytest.approx(0.26)  # no description recorded: no sensor range_min, only the rim
