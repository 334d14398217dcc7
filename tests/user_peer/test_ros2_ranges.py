"""The sonar ring as one ``sensor_msgs/Range`` per transducer (user_peer.ros2.ranges): each transducer's frame sits on
the rim at its angle, so its range along x lands where the ring's LaserScan puts the same echo; the field of view is
the sim's fan; a missing echo is +inf; a real rclpy subscriber gets each transducer's message on ``/NS/ID/sonar_I``
in ``NS/ID/sonar_I``, and a topic nobody reads is not published."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Range

from fabric.interfaces import Header, RobotInfo, Scan, SonarInfo, WorldInfo
from robofabric.testing import wait_until
from sim_peer.sensors import Ultrasonic
from user_peer.ros2.ranges import BEAM_HALF_WIDTH, RangesOut, transducer_frames

ANGLES = np.radians([0.0, 45.0, 90.0, 135.0, 180.0, -135.0, -90.0, -45.0])
SONAR = SonarInfo(ANGLES, 0.26, 0.12, 0.02, 3.0, center=np.array([0.05, 0.0]))


def _yaw(q) -> float:
    x, y, z, w = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def test_the_field_of_view_is_the_sims_fan():
    assert BEAM_HALF_WIDTH == pytest.approx(Ultrasonic.BEAM)


@pytest.mark.parametrize("r", [0.0, 0.4, 2.5])
def test_a_transducers_range_lands_where_the_rings_scan_puts_its_echo(r):
    frames = transducer_frames("base1", SONAR)
    assert [f.child for f in frames] == [f"base1/sonar_{i}" for i in range(8)] and {f.parent for f in frames} == {
        "base1/sonar"
    }
    for f, a in zip(frames, ANGLES):
        yaw = _yaw(f.rotation)
        tip = np.array(f.translation[:2]) + r * np.array([math.cos(yaw), math.sin(yaw)])
        # the LaserScan /base1/sonar: the same echo at angle a, range r + the ring's radius from its centre
        np.testing.assert_allclose(tip, (r + 0.26) * np.array([math.cos(a), math.sin(a)]), atol=1e-12)


def _world(sonar: SonarInfo | None) -> WorldInfo:
    robot = RobotInfo(
        "base1",
        "reeman",
        "mobile",
        np.zeros(4),
        ("wheel_left", "wheel_right"),
        np.zeros(2),
        np.zeros(2),
        np.zeros(2),
        sonar=sonar,
    )
    return WorldInfo("w", "combined", 0.002, {"scan": 20.0}, (robot,))


def test_a_ros_node_gets_each_transducer_as_a_range_and_an_unread_one_is_not_sent(monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ctx = rclpy.Context()
    ctx.init(domain_id=1 + (os.getpid() * 7 + 60) % 100)
    node = rclpy.create_node("ranges_test", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    got: list[Range] = []
    try:
        out = RangesOut(node, "class1", "class1/")
        out.describe(_world(SONAR))
        node.create_subscription(Range, "/class1/base1/sonar_2", got.append, qos_profile_sensor_data)
        ranges = [0.5, 1.25, 0.75, 3.0, 3.0, 2.0, 0.3, 1.0]  # 3.0: the sonar's range_max, no echo
        scan = Scan.from_ranges(
            ranges, angle_min=0.0, angle_increment=math.radians(45), range_max=3.0, header=Header(stamp=12.5)
        )

        def sent() -> bool:
            out.on_scan("base1", "rf/w/robot/base1/sonar", scan, 12_500_000_000)
            ex.spin_once(timeout_sec=0.1)
            return bool(got)

        wait_until(sent, timeout=30, what="sonar_2's Range on the subscriber")
        m = got[-1]
        assert (m.header.frame_id, m.header.stamp.sec, m.header.stamp.nanosec) == (
            "class1/base1/sonar_2",
            12,
            500_000_000,
        )
        assert m.radiation_type == Range.ULTRASOUND and m.field_of_view == pytest.approx(math.radians(30))
        assert (m.min_range, m.max_range, m.range) == pytest.approx((0.02, 3.0, 0.75))
        before = out.sent
        out.on_scan("base1", "rf/w/robot/base1/sonar", scan, 12_500_000_000)
        assert out.sent - before == 1  # only sonar_2 has a reader: the seven others are not published
        # no echo: +inf (REP 117); the subscriber's transducer 3 would read it
        node.create_subscription(Range, "/class1/base1/sonar_3", got.append, qos_profile_sensor_data)
        wait_until(
            lambda: sent() and any(g.header.frame_id.endswith("sonar_3") for g in got),
            timeout=30,
            what="sonar_3's Range",
        )
        assert all(math.isinf(g.range) for g in got if g.header.frame_id.endswith("sonar_3"))
        # the robot loses its ring (a new description): its topics go
        out.describe(_world(None))
        assert node.count_publishers("/class1/base1/sonar_2") == 0
    finally:
        ex.shutdown()
        node.destroy_node()
        ctx.try_shutdown()


def test_export_to_ros2_writes_each_transducer_as_the_bridge_does_its_frames_once_on_tf_static(tmp_path):
    """``export --to ros2``: the same topics, frames, field of view, limits and misses as the live Ranges above,
    and the transducers' frames (the live /tf_static's, transducer_frames) once on /tf_static, under base1/sonar."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from user_peer.catalog import RobotCatalog
    from user_peer.openfmt.ros2 import Ros2Writer

    catalog = RobotCatalog(None)
    catalog.world_info = _world(SONAR)
    ranges = [0.5, 1.25, 0.75, 3.0, 3.0, 2.0, 0.3, 1.0]
    with Ros2Writer(tmp_path / "r.mcap", catalog=catalog) as w:
        for stamp in (12.5, 12.55):
            w.write(
                "rf/w/robot/base1/sonar",
                Scan.from_ranges(
                    ranges, angle_min=0.0, angle_increment=math.radians(45), range_max=3.0, header=Header(stamp=stamp)
                ),
                0,
            )
    got: dict[str, list] = {}
    with open(tmp_path / "r.mcap", "rb") as f:
        for _s, channel, _m, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            got.setdefault(channel.topic, []).append(m)
    for i, r in enumerate(ranges):
        msgs = got[f"/base1/sonar_{i}"]
        assert [(m.header.stamp.sec, m.header.stamp.nanosec) for m in msgs] == [(12, 500_000_000), (12, 550_000_000)]
        for m in msgs:
            assert m.header.frame_id == f"base1/sonar_{i}" and m.radiation_type == Range.ULTRASOUND
            assert (m.field_of_view, m.min_range, m.max_range) == pytest.approx((math.radians(30), 0.02, 3.0))
            assert m.range == (math.inf if r == 3.0 else pytest.approx(r))
    (static,) = got["/tf_static"]  # once: the ring did not change
    sent = {
        t.child_frame_id: (
            t.header.frame_id,
            (t.transform.translation.x, t.transform.translation.y),
            (t.transform.rotation.z, t.transform.rotation.w),
        )
        for t in static.transforms
    }
    assert sent == {
        f.child: (f.parent, pytest.approx(f.translation[:2]), pytest.approx(f.rotation[2:]))
        for f in transducer_frames("base1", SONAR)
    }
