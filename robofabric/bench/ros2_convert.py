"""``robofabric bench ros2 --convert``: what one message costs the bridge in Python, by stream, in this process.

For a LIDAR scan (360 rays), a base's odometry and a 6-joint state: decoding the fabric's bytes, building the
rclpy message the way the bridge does (:mod:`user_peer.ros2.direct`: in place, one reused message per topic)
and the way it did before (the export's dict, then ``fill`` into a new message), and publishing it (a real rclpy
publisher, no subscriber). Microseconds of this thread's CPU per message (``time.thread_time``: a loaded
machine's waits for a core are not counted), the median of five rounds. A figure of the bridge's Python cost,
not of zenoh's or DDS's delivery.
"""

from __future__ import annotations

import os
import statistics
import time
from typing import Any, Callable

import numpy as np

__all__ = ["measure", "table"]


def _us(fn: Callable[[], Any], n: int) -> float:
    rounds = []
    for _ in range(5):
        t = time.thread_time()
        for _ in range(n):
            fn()
        rounds.append((time.thread_time() - t) / n * 1e6)
    return statistics.median(rounds)


def measure(n: int = 2000) -> list[tuple[str, float, float, float, float]]:
    """(stream, decode, build in place, build through the export's dict, publish), microseconds per message."""
    import rclpy
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import JointState as RosJointState
    from sensor_msgs.msg import LaserScan

    from fabric.codec import decode, encode
    from fabric.interfaces import Header, JointState, Pose, Scan
    from fabric.interfaces.geometry import quaternion_from_yaw
    from user_peer.openfmt.ros2 import ros2_message
    from user_peer.ros2 import direct
    from user_peer.ros2.fill import fill

    rng = np.random.default_rng(1)
    h = Header(12.5, time.time_ns(), 7, "sim")
    scan = Scan(-np.pi, 2 * np.pi / 360, 8.0, (rng.random(360) * 8000).astype(np.uint16), h)
    pose = Pose(
        np.array([1.0, 2.0, 0.0]),
        quaternion_from_yaw(0.7),
        np.array([0.3, 0.1, 0.0]),
        np.array([0.0, 0.0, 0.2]),
        header=h,
    )
    joints = JointState(tuple(f"joint_{i}" for i in range(1, 7)), rng.random(6), rng.random(6), h)
    cases = [
        (
            "scan",
            "rf/w/robot/base1/scan",
            scan,
            LaserScan,
            lambda o: direct.laser_scan(o, "base1/laser", scan, 5, 0.05, 0.0),
            {"range_min": 0.05},
        ),
        (
            "pose (odom)",
            "rf/w/robot/base1/pose",
            pose,
            Odometry,
            lambda o: direct.odometry(o, "base1", pose, 5),
            {"kind": "mobile"},
        ),
        (
            "joints",
            "rf/w/robot/arm1/joints",
            joints,
            RosJointState,
            lambda o: direct.joint_state(o, "arm1", joints, 5),
            {},
        ),
    ]
    own_context = not rclpy.ok()
    if own_context:
        rclpy.init()
    node = rclpy.create_node(f"bench_ros2_convert_{os.getpid()}")
    out = []
    try:
        for name, key, msg, cls, build, kw in cases:
            raw, reused, pub = encode(msg), cls(), node.create_publisher(cls, f"/bench_convert/{name.split()[0]}", 10)
            out.append(
                (
                    name,
                    _us(lambda: decode(raw), n),
                    _us(lambda: build(reused), n),
                    _us(lambda: fill(cls(), ros2_message(key, msg, 5, **kw)[1]), n),
                    _us(lambda: pub.publish(reused), n),
                )
            )
    finally:
        node.destroy_node()
        if own_context:
            rclpy.shutdown()
    return out


def table(rows: list[tuple[str, float, float, float, float]]) -> list[str]:
    lines = [
        "| stream (CPU per message) | decode (µs) | build in place (µs) | build via the export's dict (µs) | publish (µs) |",
        "|---|---|---|---|---|",
    ]
    lines += [f"| {s} | {d:.1f} | {b:.1f} | {x:.1f} | {p:.1f} |" for s, d, b, x, p in rows]
    return lines
