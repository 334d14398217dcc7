"""The ROS 2 side of ``robofabric bench ros2``: a plain rclpy node that notes when each bridged message arrives.

``python -m robofabric.bench.ros2_listen --robots base0,base1 --seconds 10 --out FILE``: subscribes to every
robot's ``scan`` (sensor-data QoS), ``odom`` and ``joint_states``, prints ``ready``, and after ``--seconds``
writes one line per message, ``TOPIC STAMP_NS ARRIVAL_NS`` (arrival: ``time.time_ns()``, the clock the
benchmark's zenoh subscriber reads too), then exits. Kept in memory until the end: no file writes while it
measures. Imports rclpy only. ``--executor events`` (the default) spins with rclpy's EventsExecutor
(``rclpy.experimental``), whose cost per callback is a fraction of the SingleThreadedExecutor's
(``--executor single``): on two loaded cores the latter fell behind 1,300 messages a second by itself, and a
late callback reads as the bridge's latency.
"""

from __future__ import annotations

import argparse
import time


def main() -> None:
    import rclpy
    from nav_msgs.msg import Odometry
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import JointState, LaserScan

    ap = argparse.ArgumentParser()
    ap.add_argument("--robots", required=True)
    ap.add_argument("--seconds", type=float, required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--executor", choices=("events", "single"), default="events")
    args = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("bench_ros2_listen")
    got: list[tuple[str, int, int]] = []
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    for rid in args.robots.split(","):
        for leaf, cls, qos in (("scan", LaserScan, qos_profile_sensor_data), ("odom", Odometry, reliable),
                               ("joint_states", JointState, reliable)):
            topic = f"/{rid}/{leaf}"
            node.create_subscription(
                cls, topic,
                lambda m, t=topic: got.append((t, m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, time.time_ns())),
                qos)
    if args.executor == "events":
        from rclpy.experimental import EventsExecutor

        executor = EventsExecutor()
    else:
        executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    print("ready", flush=True)
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    with open(args.out, "w") as f:
        f.writelines(f"{t} {s} {a}\n" for t, s, a in got)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
