"""``export --to ros2`` read by a decoder we did not write: rosbags (its own CDR codec and ROS 2 Kilted's standard
message definitions) decodes every message of an exported MCAP, and its values are the fabric's: joint states,
odometry with the twist in the base's frame, a LIDAR scan with +inf for a missing echo, the sonar's ranges from
the ring's centre, the map, the path, /tf, /clock (the sim's time); the schemas the file carries parse in rosbags' own msg parser."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

import robots
from fabric.interfaces import Header, JointState, OccupancyGrid, Path, Pose, Scan
from fabric.interfaces.geometry import quaternion_from_yaw
from user_peer.openfmt.ros2 import Ros2Writer

T0 = 1_760_000_000_000_000_000


def source() -> list[tuple[str, object]]:
    names = robots.load("meca500").joint_names
    out: list[tuple[str, object]] = []
    for i in range(1, 4):
        h = Header(0.1 * i, T0 + i, i, "sim-1")
        out.append(("rf/w/robot/arm1/joints", JointState(names, np.linspace(-0.5, 0.5, 6) * i, np.zeros(6), h)))
        out.append(
            (
                "rf/w/robot/base1/pose",
                Pose(
                    np.array([1.0, 0.5 * i, 0.0]),
                    quaternion_from_yaw(math.pi / 2),
                    np.array([0.0, 0.3, 0.0]),
                    np.array([0.0, 0.0, 0.2]),
                    header=h,
                ),
            )
        )
        out.append(
            ("rf/w/robot/base1/scan", Scan(-1.0, 0.5, 8.0, np.array([1000, 8000, 2500 + i], dtype=np.uint16), h))
        )
        out.append(("rf/w/robot/base1/sonar", Scan(0.0, 0.5, 3.0, np.array([400, 3000], dtype=np.uint16), h)))
    out.append(
        ("rf/w/map/map", OccupancyGrid(0.1, np.array([1.0, 2.0, 0.0]), np.array([[0, 100, 255]], dtype=np.uint8)))
    )
    out.append(("rf/w/robot/base1/path", Path(np.array([0.0, 1.0]), np.array([0.0, 2.0]), np.array([0.0, 0.5]))))
    return out


def test_rosbags_decodes_the_ros2_export_with_the_standard_definitions_and_the_fabrics_values(tmp_path):
    with Ros2Writer(tmp_path / "r.mcap", scene="combined") as w:
        for key, msg in source():
            w.write(key, msg, T0)
    store = get_typestore(Stores.ROS2_KILTED)  # the standard definitions, not the file's
    got: dict[str, list] = {}
    with open(tmp_path / "r.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            get_types_from_msg(schema.data.decode(), schema.name)  # the file's schema parses in rosbags' parser
            got.setdefault(channel.topic, []).append(store.deserialize_cdr(message.data, schema.name))
    assert {
        "/arm1/joint_states",
        "/base1/odom",
        "/base1/scan",
        "/base1/sonar",
        "/map",
        "/base1/path",
        "/tf",
        "/clock",
        "/tf_static",
        "/base1/sonar_0",
        "/base1/sonar_1",
    } <= set(got)
    src = {}
    for key, msg in source():
        src.setdefault(key, []).append(msg)

    for ros, msg in zip(got["/arm1/joint_states"], src["rf/w/robot/arm1/joints"], strict=True):
        assert list(ros.name) == list(msg.names) and np.array_equal(ros.position, msg.q)
        assert (ros.header.frame_id, ros.header.stamp.sec * 10**9 + ros.header.stamp.nanosec) == (
            "arm1/base_link",
            round(msg.header.stamp * 1e9),
        )
    for ros, msg in zip(got["/base1/odom"], src["rf/w/robot/base1/pose"], strict=True):
        assert (ros.header.frame_id, ros.child_frame_id) == ("base1/odom", "base1/base_link")
        assert ros.pose.pose.position.y == msg.position[1]
        # facing +y at 0.3 m/s in the world: 0.3 m/s forward in the base's own frame (REP 105)
        assert ros.twist.twist.linear.x == pytest.approx(0.3) and ros.twist.twist.linear.y == pytest.approx(
            0.0, abs=1e-12
        )
        assert ros.twist.twist.angular.z == pytest.approx(0.2)
    for ros, msg in zip(got["/base1/scan"], src["rf/w/robot/base1/scan"], strict=True):
        assert ros.header.frame_id == "base1/laser" and ros.range_max == pytest.approx(8.0)
        assert ros.ranges.tolist() == pytest.approx([1.0, math.inf, msg.ranges[2]])  # no echo: +inf (REP 117)
    for ros in got["/base1/sonar"]:  # measured from the rim of the reeman's ring (0.26 m): given from its centre
        assert ros.header.frame_id == "base1/sonar" and ros.ranges.tolist() == pytest.approx([0.66, math.inf])
    (grid,) = got["/map"]
    assert grid.data.tolist() == [0, 100, -1] and (grid.info.width, grid.info.height) == (3, 1)
    assert grid.info.resolution == pytest.approx(0.1) and grid.header.frame_id == "map"
    (path,) = got["/base1/path"]
    assert [(p.pose.position.x, p.pose.position.y) for p in path.poses] == [(0.0, 0.0), (1.0, 2.0)]
    clock = [c.clock.sec * 10**9 + c.clock.nanosec for c in got["/clock"]]  # the sim's time, as the bridge's /clock
    assert clock == [round(0.1 * i * 1e9) for i in range(1, 4)]
    # each transducer a Range in its frame on the rim (no description: the scan's angles 0 and 0.5 rad)
    assert [(r.header.frame_id, r.range, r.radiation_type) for r in got["/base1/sonar_0"]] == [
        ("base1/sonar_0", pytest.approx(0.4), 0)
    ] * 3
    assert all(
        math.isinf(r.range) and r.field_of_view == pytest.approx(math.radians(30)) for r in got["/base1/sonar_1"]
    )
    static = {t.child_frame_id: t for m in got["/tf_static"] for t in m.transforms}
    assert static["base1/sonar_1"].header.frame_id == "base1/sonar"
    rim = static["base1/sonar_1"].transform.translation
    assert (rim.x, rim.y) == pytest.approx((0.26 * math.cos(0.5), 0.26 * math.sin(0.5)))
    frames = {t.child_frame_id: t.header.frame_id for m in got["/tf"] for t in m.transforms}
    assert (
        frames["base1/odom"] == "map"
        and frames["base1/base_link"] == "base1/odom"
        and frames["base1/laser"] == "base1/base_link"
    )
    assert frames["arm1/link_1"] == "arm1/base_link" and frames["arm1/flange"] == "arm1/link_6"
