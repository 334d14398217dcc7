"""The viewer peer over real Zenoh writes an .rrd that Rerun's own loader reads back."""

import math
import threading

import numpy as np

from fabric import keys
from fabric.interfaces import Header, JointState, OccupancyGrid, OwnershipRecord, Path, Pose, Scan
from robofabric.testing import client_config, wait_until
from user_peer.viewer import Viewer, ViewerOptions
from userpeer_rrd import entities_with_data, rows_per_entity

ARM_JOINTS = ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6")


def test_viewer_saves_robots_scans_maps_paths(world, router, connect, tmp_path):
    out = tmp_path / "view.rrd"
    pub = connect("sim", "fake-sim")
    viewer = Viewer(client_config(world, router[1]), ViewerOptions(save=out, max_hz=0), peer_id="viewer-test")
    stop = threading.Event()
    t = threading.Thread(target=viewer.run, args=(stop,), daemon=True)
    t.start()
    wait_until(lambda: ("viewer", "viewer-test") in pub.live_peers("viewer"), what="viewer token")
    wait_until(lambda: viewer.fab.counters["received"] >= 0 and t.is_alive(), what="viewer running")

    def publish_all(i: int) -> None:
        h = Header(stamp=0.05 * i, wall_ns=10**18 + i * 50_000_000, seq=i, source="fake-sim")
        pub.publish(keys.robot_joints(world, "arm1"), JointState(ARM_JOINTS, np.full(6, 0.01 * i), np.zeros(6), h))
        yaw = 0.1 * i
        pub.publish(
            keys.robot_pose(world, "base1"),
            Pose([0.1 * i, 0, 0], [math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)], [0.2, 0, 0], [0, 0, 0.1], header=h),
        )
        pub.publish(
            keys.robot_scan(world, "base1"),
            Scan.from_ranges(
                np.linspace(1, 3, 240), angle_min=-1.178, angle_increment=2.356 / 239, range_max=8.0, header=h
            ),
        )
        pub.publish(
            keys.robot_stream(world, "base1", "sonar"),
            Scan.from_ranges(np.full(8, 0.5), angle_min=0.0, angle_increment=math.pi / 4, range_max=3.0, header=h),
        )
        if i % 5 == 0:
            pub.publish(
                keys.map_key(world, "base1"), OccupancyGrid(0.05, [-5, -5, 0], np.full((200, 200), 255, np.uint8), h)
            )
            pub.publish(keys.robot_path(world, "base1"), Path([0, 1, 2], [0, 0.5, 1], [0, 0.4, 0.8], header=h))
            pub.publish(keys.object_pose(world, "target", "alice"), Pose([0.2, 0.0, 0.3], header=h))
            pub.publish(keys.own(world, "arm1"), OwnershipRecord("arm1", owner="alice", epoch=1 + i))

    i = 0

    def seen_all():
        nonlocal i
        publish_all(i)
        i += 1
        c = viewer.logger.counts
        # and a stream's rate filed: it takes a period (0.5 s) of arrivals, which three of each kind need not span
        # (a whole run at load: the viewer subscribed late, took the latched map at once, and filed no rate)
        kinds = ("JointState", "Pose", "Scan", "OccupancyGrid", "Path", "OwnershipRecord")
        return all(c[k] >= 3 for k in kinds) and viewer.logger.rates.filed > 0

    wait_until(
        seen_all, timeout=20, interval=0.05, what="viewer logging every kind", seen=lambda: dict(viewer.logger.counts)
    )
    stop.set()
    t.join(10)
    viewer.close()

    rows = rows_per_entity(out)
    assert rows["/world/robots/base1/scan"] >= 3
    assert rows["/world/robots/base1/sonar"] >= 3  # the ultrasonic ring apart from the LIDAR
    assert rows["/world/robots/base1/base"] >= 3
    assert rows["/plots/age/base1"] >= 3  # the age (since arrival, local clock) each base pose was drawn with (Eq. 8)
    assert rows["/map/base1"] >= 3
    assert rows["/world/robots/base1/path"] >= 3
    assert rows["/map/base1/paths/base1"] >= 1
    assert rows["/world/objects/target"] >= 1
    assert rows["/plots/joints/arm1"] >= 3  # the arm's six joints, one series each
    assert rows["/world/robots/arm1/label"] >= 1 or rows["/world/robots/base1/base/label"] >= 1
    assert rows["/ownership/arm1"] >= 1
    assert entities_with_data(out, "/plots/rates/")
