"""A plain ROS 2 node for the bridge's model, trajectory and refusal tests: it imports nothing from robofabric.

It writes one JSON line per message to ``--out``: each robot's ``robot_description`` (latched String), its
``joint_states`` (names, positions, the wall time it came), ``/rosout`` and the ``--clocks`` topics. While ``--control/cmd_vel`` exists
("v omega", ``nan`` allowed) it publishes that ``geometry_msgs/Twist`` (``--stamped``: ``TwistStamped``) on ``/BASE/cmd_vel`` at 10 Hz; when
``--control/trajectory`` appears (JSON ``[names, [[positions, seconds], ...]]``) it publishes that
``trajectory_msgs/JointTrajectory`` on ``/ARM/joint_trajectory`` once, writes ``trajectory_sent`` and removes the
file; when ``--control/goal`` appears ("x y") it publishes that ``geometry_msgs/PoseStamped`` (frame ``map``) on
``/goal_pose`` once, as RViz's 2D Goal Pose does; it writes ``BASE``'s odometry (frames, covariance) and path, its
scan's frame, stamp and timing, its sonar transducer 2 (``sensor_msgs/Range``) and each robot's latched ``owner``.
``--ns NS`` puts the robots' topics (and goal_pose) under ``/NS``. ``--tf`` reads ``/tf`` and ``/tf_static`` as
``tf2_msgs/msg/TFMessage`` and writes each transform's parent, child and stamp. When ``--control/call`` appears
(a service name) it calls that ``std_srvs/Trigger`` service once it is there and writes the response. Runs until
SIGTERM.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import rclpy
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry, Path
from rcl_interfaces.msg import Log
from rosgraph_msgs.msg import Clock
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import JointState, LaserScan, Range
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--control", required=True)
    ap.add_argument("--robots", default="arm1,base1")
    ap.add_argument("--arm", default="arm1")
    ap.add_argument("--base", default="base1")
    ap.add_argument("--clocks", default="/clock", help="clock topics to listen to, comma-separated")
    ap.add_argument("--stamped", action="store_true", help="cmd_vel as geometry_msgs/TwistStamped")
    ap.add_argument("--ns", default="", help="the bridge's --namespace")
    ap.add_argument("--tf", action="store_true", help="read /tf and /tf_static (tf2_msgs/msg/TFMessage)")
    args = ap.parse_args()
    out = open(args.out, "a", buffering=1)

    def write(**fields) -> None:
        out.write(json.dumps({"wall": time.monotonic(), **fields}) + "\n")

    def under(name: str) -> str:
        return f"/{args.ns}/{name}" if args.ns else f"/{name}"

    rclpy.init()
    node = Node("plain_ros2_listener")
    reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    for rid in args.robots.split(","):
        node.create_subscription(
            String, under(f"{rid}/owner"), lambda m, r=rid: write(topic="owner", robot=r, owner=m.data), latched
        )
        node.create_subscription(
            String,
            under(f"{rid}/robot_description"),
            lambda m, r=rid: write(topic="robot_description", robot=r, urdf=m.data),
            latched,
        )
        node.create_subscription(
            JointState,
            under(f"{rid}/joint_states"),
            lambda m, r=rid: write(
                topic="joint_states",
                robot=r,
                frame=m.header.frame_id,
                name=list(m.name),
                stamp=m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
                position=list(m.position),
            ),
            reliable,
        )
    for topic in args.clocks.split(","):
        node.create_subscription(
            Clock,
            topic,
            lambda m, t=topic: write(
                topic="clock",
                on=t,
                ns=int(m.clock.sec) * 1_000_000_000 + int(m.clock.nanosec),
                publishers=node.count_publishers(t),
            ),
            QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE),
        )
    node.create_subscription(
        Log,
        "/rosout",
        lambda m: write(topic="rosout", name=m.name, level=int(m.level), msg=m.msg),
        QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE),
    )
    node.create_subscription(
        Odometry,
        under(f"{args.base}/odom"),
        lambda m: write(
            topic="odom",
            x=m.pose.pose.position.x,
            y=m.pose.pose.position.y,
            frame=m.header.frame_id,
            child=m.child_frame_id,
            pose_cov=list(m.pose.covariance),
            twist_cov=list(m.twist.covariance),
        ),
        reliable,
    )
    node.create_subscription(
        LaserScan,
        under(f"{args.base}/scan"),
        lambda m: write(
            topic="scan",
            frame=m.header.frame_id,
            scan_time=m.scan_time,
            stamp=m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
            time_increment=m.time_increment,
        ),
        qos_profile_sensor_data,
    )
    node.create_subscription(
        Range,
        under(f"{args.base}/sonar_2"),
        lambda m: write(
            topic="range",
            frame=m.header.frame_id,
            range=m.range,
            fov=m.field_of_view,
            kind=int(m.radiation_type),
            min=m.min_range,
            max=m.max_range,
        ),
        qos_profile_sensor_data,
    )
    node.create_subscription(
        Path,
        under(f"{args.base}/path"),
        lambda m: write(
            topic="path",
            frame=m.header.frame_id,
            n=len(m.poses),
            end=[m.poses[-1].pose.position.x, m.poses[-1].pose.position.y] if m.poses else None,
        ),
        latched,
    )
    if args.tf:
        from tf2_msgs.msg import TFMessage  # as any ROS 2 node reads it; missing, this node fails at start

        def transforms(m: TFMessage, static: bool) -> None:
            write(
                topic="tf",
                static=static,
                transforms=[
                    [t.header.frame_id, t.child_frame_id, t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec]
                    for t in m.transforms
                ],
            )

        node.create_subscription(
            TFMessage,
            under("tf"),
            lambda m: transforms(m, False),
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE),
        )
        node.create_subscription(TFMessage, under("tf_static"), lambda m: transforms(m, True), latched)
    goal = node.create_publisher(PoseStamped, under("goal_pose"), 10)
    goal_file = os.path.join(args.control, "goal")
    cmd = node.create_publisher(TwistStamped if args.stamped else Twist, under(f"{args.base}/cmd_vel"), 10)
    trajectory = node.create_publisher(JointTrajectory, under(f"{args.arm}/joint_trajectory"), 10)
    cmd_file = os.path.join(args.control, "cmd_vel")
    trajectory_file = os.path.join(args.control, "trajectory")
    call_file = os.path.join(args.control, "call")
    clients: dict = {}

    def call() -> None:
        try:
            with open(call_file) as f:
                name = f.read().strip()
        except FileNotFoundError:
            return
        if not name:
            return  # being written
        from std_srvs.srv import Trigger  # as any ROS 2 node calls it; missing, this node fails here

        client = clients.get(name) or clients.setdefault(name, node.create_client(Trigger, name))
        if not client.service_is_ready():
            return  # not discovered yet: again at the next tick
        os.unlink(call_file)
        client.call_async(Trigger.Request()).add_done_callback(
            lambda f: write(topic="call", service=name, success=f.result().success, message=f.result().message)
        )

    def send_goal() -> None:
        try:
            with open(goal_file) as f:
                x, y = (float(v) for v in f.read().split())
        except (FileNotFoundError, ValueError):
            return
        os.unlink(goal_file)
        g = PoseStamped()
        g.header.frame_id = "map"  # RViz's 2D Goal Pose, fixed frame map
        g.pose.position.x, g.pose.position.y, g.pose.orientation.w = x, y, 1.0
        goal.publish(g)
        write(topic="goal_sent", subscribers=goal.get_subscription_count())

    def tick() -> None:
        send_goal()
        call()
        try:
            with open(trajectory_file) as f:
                names, points = json.load(f)
            os.unlink(trajectory_file)
            t = JointTrajectory()
            t.joint_names = list(names)
            for positions, seconds in points:
                p = JointTrajectoryPoint()
                p.positions = [float(v) for v in positions]
                p.time_from_start.sec, p.time_from_start.nanosec = int(seconds), int(round((seconds % 1) * 1e9))
                t.points.append(p)
            trajectory.publish(t)
            write(topic="trajectory_sent", subscribers=trajectory.get_subscription_count())
        except (FileNotFoundError, ValueError):
            pass
        try:
            with open(cmd_file) as f:
                v, w = (float(x) for x in f.read().split())
        except (FileNotFoundError, ValueError):
            return
        t = TwistStamped() if args.stamped else Twist()
        twist = t.twist if args.stamped else t
        twist.linear.x, twist.angular.z = v, w
        cmd.publish(t)
        write(topic="cmd_vel_sent", subscribers=cmd.get_subscription_count())

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
