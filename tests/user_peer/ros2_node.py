"""A plain ROS 2 node for tests/user_peer/test_ros2_bridge.py: it imports nothing from robofabric.

It listens to what ``robofabric ros2`` publishes and writes one JSON line per message to ``--out``
(topic, stamp in ns, the values the test compares); while the file ``--control/drive`` exists it
publishes ``geometry_msgs/Twist`` on ``/BASE/cmd_vel`` at 10 Hz with the "v omega" the file holds, as a
teleop node would, and stops publishing when the file is removed; while ``--control/joints`` exists (JSON
``[names, positions]``) it publishes that ``sensor_msgs/JointState`` on ``/ARM/joint_command``; while
``--control/trajectory`` appears or changes (JSON ``[names, [positions, ...]]``) it publishes once a
``trajectory_msgs/JointTrajectory`` of those points, 1 s apart, on ``/ARM/joint_trajectory`` (a new one replaces
the one the bridge plays). Runs until SIGTERM.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import OccupancyGrid, Odometry
from rcl_interfaces.msg import Log
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint


def stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--control", required=True)
    ap.add_argument("--arm", default="arm1")
    ap.add_argument("--base", default="base1")
    args = ap.parse_args()
    out = open(args.out, "a", buffering=1)

    def write(**fields) -> None:
        out.write(json.dumps(fields) + "\n")

    rclpy.init()
    node = Node("plain_ros2_test_node")
    reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(
        JointState,
        f"/{args.arm}/joint_states",
        lambda m: write(
            topic="joint_states",
            stamp=stamp_ns(m.header),
            frame=m.header.frame_id,
            name=list(m.name),
            position=list(m.position),
        ),
        reliable,
    )
    node.create_subscription(
        LaserScan,
        f"/{args.base}/scan",
        lambda m: write(
            topic="scan",
            stamp=stamp_ns(m.header),
            frame=m.header.frame_id,
            angle_min=m.angle_min,
            angle_increment=m.angle_increment,
            range_min=m.range_min,
            range_max=m.range_max,
            ranges=[float(r) for r in m.ranges],
        ),
        qos_profile_sensor_data,
    )
    node.create_subscription(
        LaserScan,
        f"/{args.base}/sonar",
        lambda m: write(
            topic="sonar",
            stamp=stamp_ns(m.header),
            frame=m.header.frame_id,
            range_min=m.range_min,
            range_max=m.range_max,
            ranges=[float(r) for r in m.ranges],
        ),
        qos_profile_sensor_data,
    )
    node.create_subscription(
        Odometry,
        f"/{args.base}/odom",
        lambda m: write(
            topic="odom",
            stamp=stamp_ns(m.header),
            frame=m.header.frame_id,
            child=m.child_frame_id,
            position=[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z],
            v=m.twist.twist.linear.x,
        ),
        reliable,
    )
    node.create_subscription(
        Clock,
        "/clock",
        lambda m: write(topic="clock", ns=int(m.clock.sec) * 1_000_000_000 + int(m.clock.nanosec)),
        QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT),
    )
    node.create_subscription(
        OccupancyGrid,
        "/map",
        lambda m: write(
            topic="map",
            frame=m.header.frame_id,
            resolution=m.info.resolution,
            width=m.info.width,
            height=m.info.height,
            data=[int(v) for v in m.data],
        ),
        latched,
    )
    node.create_subscription(
        Log, "/rosout", lambda m: write(topic="rosout", name=m.name, level=int(m.level), msg=m.msg), reliable
    )
    cmd = node.create_publisher(Twist, f"/{args.base}/cmd_vel", 10)
    joint_cmd = node.create_publisher(JointState, f"/{args.arm}/joint_command", 10)
    drive_file = os.path.join(args.control, "drive")
    joints_file = os.path.join(args.control, "joints")
    trajectory = node.create_publisher(JointTrajectory, f"/{args.arm}/joint_trajectory", 10)
    trajectory_file = os.path.join(args.control, "trajectory")

    sent = [""]  # the trajectory file's text last published: a trajectory is sent once, as a ROS client does

    def send_trajectory() -> None:
        try:
            with open(trajectory_file) as f:
                text = f.read()
            names, points = json.loads(text)
        except (FileNotFoundError, ValueError):
            return
        if text == sent[0]:
            return
        sent[0] = text
        t = JointTrajectory()
        t.joint_names = list(names)
        for i, positions in enumerate(points):
            p = JointTrajectoryPoint()
            p.positions = [float(v) for v in positions]
            p.time_from_start.sec = i + 1
            t.points.append(p)
        trajectory.publish(t)

    def tick() -> None:
        send_trajectory()
        try:
            with open(joints_file) as f:
                names, positions = json.load(f)
            j = JointState()
            j.name, j.position = list(names), [float(v) for v in positions]
            joint_cmd.publish(j)
        except (FileNotFoundError, ValueError):
            pass
        try:
            with open(drive_file) as f:
                v, w = (float(x) for x in f.read().split())
        except (FileNotFoundError, ValueError):
            return
        t = Twist()
        t.linear.x, t.angular.z = v, w
        cmd.publish(t)
        write(topic="cmd_vel_sent", v=v, w=w, subscribers=cmd.get_subscription_count())

    node.create_timer(0.1, tick)
    write(topic="ready")
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        out.close()
        sys.exit(0)


if __name__ == "__main__":
    main()
