"""The ROS 2 bridge: one robofabric login's view of a world, as ROS 2 topics, and its commands from ROS 2.

Out (every robot of the world, followed as sims and robots come and go)::

    /NS/ROBOT/joint_states  sensor_msgs/JointState   from rf/W/robot/ROBOT/joints
    /NS/ROBOT/scan          sensor_msgs/LaserScan    from rf/W/robot/ROBOT/scan     (sensor-data QoS: best effort)
    /NS/ROBOT/sonar         sensor_msgs/LaserScan    from rf/W/robot/ROBOT/sonar    (ranges from the ring's centre)
    /NS/ROBOT/odom          nav_msgs/Odometry        from a mobile base's rf/W/robot/ROBOT/pose
    /NS/ROBOT/pose          geometry_msgs/PoseStamped from an arm's pose (its flange)
    /NS/ROBOT/path          nav_msgs/Path            from rf/W/robot/ROBOT/path     (reliable, transient local)
    /NS/map                 nav_msgs/OccupancyGrid   from rf/W/map/map (other maps: /NS/maps/NAME; reliable, transient local)
    /NS/object/ID/pose      geometry_msgs/PoseStamped from rf/W/object/ID/pose/by/*
    /clock                  rosgraph_msgs/Clock      the sims' time (the newest header stamp of robot state)

In (acted on only for robots this login owns, as for any user; a refusal is logged on /rosout and counted)::

    /NS/ROBOT/cmd_vel        geometry_msgs/Twist     -> Base.twist(linear.x, angular.z, hold=False)
    /NS/ROBOT/joint_command  sensor_msgs/JointState  -> Arm.move_joints(positions, wait=False)

Every message is converted by :func:`user_peer.openfmt.ros2.ros2_message`, the conversion of
``export --to ros2``: frame ids, stamps (the sender's wall clock) and values are the MCAP export's. Each
``cmd_vel`` is forwarded once (``hold=False``): the sim's deadman stops a base 0.5 s after the last fresh
twist, so a ROS stream that stops, stops the base, as a ROS user expects of ``cmd_vel``.

Threads: zenoh's callbacks convert and publish (rclpy publishers may be used from any thread); the rclpy
executor runs the command callbacks and a 1 s timer that follows the world's robots.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan

from fabric import keys
from user_peer.errors import FabricUserError
from user_peer.geometry import rotation_xyzw
from user_peer.openfmt.foxglove import msg_time_ns
from user_peer.openfmt.ros2 import ros2_message, ros_topic, sensor_range_min, sonar_radius
from user_peer.ros2.fill import fill
from user_peer.world import World

__all__ = ["Ros2Bridge", "LATCHED", "RELIABLE"]

log = logging.getLogger("robofabric.ros2")

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""A map or a path: the latest is kept for late joiners (rviz2 started after the map was built), as the fabric
latches those keys."""

FOLLOW_PERIOD_S = 1.0
"""How often the bridge looks at the world's description for robots that came or went."""


class Ros2Bridge:
    """Republish ``world``'s streams on ``node`` and forward its ROS commands; ``close()`` ends it."""

    def __init__(self, world: World, node: Node, *, namespace: str = "") -> None:
        self.world = world
        self.node = node
        self.ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
        self._lock = threading.Lock()
        self._pubs: dict[str, Any] = {}  # topic -> publisher
        self._robot_topics: dict[str, set[str]] = {}  # robot -> its topics (destroyed when it leaves)
        self._inputs: dict[str, Any] = {}  # robot -> its command subscription
        self._kinds: dict[str, str] = {}  # robot -> kind ("arm", "mobile"), from the world description
        self._clock_ns = 0
        self._described: Any = None  # the last world description (each sensor's range_min), from follow()
        self.published: Counter[str] = Counter()  # topic -> messages published
        self.forwarded: Counter[str] = Counter()  # robot -> commands forwarded
        self.refused: Counter[str] = Counter()  # robot -> commands refused (not owned, rejected)
        self.unconverted = 0  # fabric messages with no ROS place (or failed to convert)
        self._event_mark = world.event_mark()
        self._subs: list[Any] = []
        self._closed = False
        self._clock_pub = node.create_publisher(Clock, "/clock", RELIABLE)
        w = world.name
        fab = world.fabric
        self.follow()  # first: the description's sensors (range_min) are known before the first scan
        self._subs = [
            fab.subscribe(keys.robot_stream_all(w, "joints"), self._on_state),
            fab.subscribe(keys.robot_stream_all(w, "scan"), self._on_state),
            fab.subscribe(keys.robot_stream_all(w, "sonar"), self._on_state),
            fab.subscribe(keys.robot_stream_all(w, "pose"), self._on_state),
            fab.subscribe(keys.robot_stream_all(w, "path"), self._on_state, history=True),
            fab.subscribe(f"{keys.world_root(w)}/map/*", self._on_state, history=True),
            fab.subscribe(keys.object_pose_all(w), self._on_state, history=True),
        ]
        self._timer = node.create_timer(FOLLOW_PERIOD_S, self._tick)

    # ------------------------------------------------------------------ out
    def _topic(self, *parts: str) -> str:
        return ros_topic("/".join([self.ns, *parts]))

    def _route(self, key: str, msg: Any) -> tuple[str, str | None, type, QoSProfile] | None:
        """(topic, robot or None, ROS message class, QoS) for fabric ``key``; None when it has no topic."""
        parts = key.split("/")  # rf/W/robot/ID/stream, rf/W/map/NAME, rf/W/object/ID/pose/by/USER
        if len(parts) == 5 and parts[2] == "robot":
            rid, stream = parts[3], parts[4]
            if stream == "joints":
                return self._topic(rid, "joint_states"), rid, JointState, RELIABLE
            if stream in ("scan", "sonar"):
                return self._topic(rid, stream), rid, LaserScan, qos_profile_sensor_data
            if stream == "path":
                return self._topic(rid, "path"), rid, Path, LATCHED
            if stream == "pose":
                if self._kinds.get(rid) == "mobile":
                    return self._topic(rid, "odom"), rid, Odometry, RELIABLE
                if self._kinds.get(rid) == "arm":
                    return self._topic(rid, "pose"), rid, PoseStamped, RELIABLE
            return None
        if len(parts) == 4 and parts[2] == "map":
            name = parts[3]
            return (self._topic("map") if name == "map" else self._topic("maps", name)), None, OccupancyGrid, LATCHED
        if len(parts) >= 5 and parts[2] == "object":
            return self._topic("object", parts[3], "pose"), None, PoseStamped, RELIABLE
        return None

    def _publisher(self, topic: str, robot: str | None, cls: type, qos: QoSProfile) -> Any:
        with self._lock:
            pub = self._pubs.get(topic)
            if pub is None and not self._closed:
                pub = self._pubs[topic] = self.node.create_publisher(cls, topic, qos)
                if robot is not None:
                    self._robot_topics.setdefault(robot, set()).add(topic)
            return pub

    def _on_state(self, key: str, msg: Any) -> None:
        """A fabric message: convert it as the MCAP export does and publish it (zenoh's thread)."""
        if self._closed or not self.node.context.ok():
            return  # stopping (Ctrl-C or SIGTERM shut rclpy's context down before the world closed): nothing to publish on
        try:
            route = self._route(key, msg)
            if route is None:
                return
            topic, robot, cls, qos = route
            scan = cls is LaserScan
            converted = ros2_message(key, msg, msg_time_ns(msg, time.time_ns()),
                                     range_min=sensor_range_min(self._described, key) if scan else 0.0,
                                     range_offset=(sonar_radius(self._described, key) or 0.0) if scan else 0.0)
            if converted is None:
                self.unconverted += 1
                return
            if cls is Odometry:
                out = self._odometry(robot or "", msg, converted[1])
            else:
                out = fill(cls(), converted[1])
            pub = self._publisher(topic, robot, cls, qos)
            if pub is None:
                return
            pub.publish(out)
            self.published[topic] += 1
            if robot is not None:
                self._tick_clock(msg)
        except Exception:  # a message that does not fit must not end the bridge's subscription
            self.unconverted += 1
            log.exception("could not publish %s on ROS 2", key)

    @staticmethod
    def _odometry(robot: str, msg: Any, pose_stamped: dict) -> Odometry:
        """A base's pose as Odometry: the PoseStamped of the export (frame ``world``), child frame the base's id,
        the twist turned from the world frame (the sim's velocities) into the base's, as REP 105 asks."""
        odom = Odometry()
        fill(odom.header, pose_stamped["header"])
        odom.child_frame_id = robot
        fill(odom.pose.pose, pose_stamped["pose"])
        o = pose_stamped["pose"]["orientation"]
        r = rotation_xyzw(np.array([o["x"], o["y"], o["z"], o["w"]]))
        v = r.T @ np.asarray(msg.linear, dtype=float)
        w = r.T @ np.asarray(msg.angular, dtype=float)
        odom.twist.twist.linear.x, odom.twist.twist.linear.y, odom.twist.twist.linear.z = (float(x) for x in v)
        odom.twist.twist.angular.x, odom.twist.twist.angular.y, odom.twist.twist.angular.z = (float(x) for x in w)
        return odom

    def _tick_clock(self, msg: Any) -> None:
        """/clock: the newest sim time seen in robot state, never going back (several sims: the furthest)."""
        stamp = float(getattr(getattr(msg, "header", None), "stamp", 0.0) or 0.0)
        ns = int(round(stamp * 1e9))
        with self._lock:
            if ns <= self._clock_ns or self._closed:
                return
            self._clock_ns = ns
        c = Clock()
        c.clock.sec, c.clock.nanosec = ns // 1_000_000_000, ns % 1_000_000_000
        self._clock_pub.publish(c)
        self.published["/clock"] += 1

    # ------------------------------------------------------------------ following the world
    def _tick(self) -> None:
        try:
            self.follow()
            self._report_rejections()
        except Exception:
            log.exception("following the world failed")

    def follow(self) -> None:
        """Give every robot of the world its command topic; drop the topics of robots that left."""
        try:
            self._described = info = self.world.info()
            entries = {r.id: r.kind for r in info.robots}
        except FabricUserError as exc:  # no sim now: keep what we have, the world's tokens tell the rest
            log.debug("no world description now: %s", exc)
            return
        for rid, kind in entries.items():
            self._kinds[rid] = kind
            if rid in self._inputs:
                continue
            if kind == "mobile":
                self._inputs[rid] = self.node.create_subscription(
                    Twist, self._topic(rid, "cmd_vel"), lambda m, r=rid: self._on_cmd_vel(r, m), RELIABLE)
            elif kind == "arm":
                self._inputs[rid] = self.node.create_subscription(
                    JointState, self._topic(rid, "joint_command"), lambda m, r=rid: self._on_joint_command(r, m), RELIABLE)
        for rid in [r for r in list(self._inputs) if r not in entries]:
            self.node.destroy_subscription(self._inputs.pop(rid))
            self._kinds.pop(rid, None)
            with self._lock:
                for topic in self._robot_topics.pop(rid, set()):
                    self.node.destroy_publisher(self._pubs.pop(topic))
            self.node.get_logger().info(f"{rid} left world {self.world.name}: its topics are gone")

    # ------------------------------------------------------------------ in
    def _refuse(self, robot: str, what: str, why: str) -> None:
        self.refused[robot] += 1
        n = self.refused[robot]
        text = f"refused {what} for {robot} ({n} refused so far): {why}"
        log.warning("%s", text)
        self.node.get_logger().warning(text, throttle_duration_sec=1.0)

    def _check_owner(self, robot: str, what: str) -> Any:
        """The robot's handle when this login may command it; else None, the refusal told."""
        try:
            handle = self.world.robot(robot)
        except FabricUserError as exc:
            self._refuse(robot, what, exc.reason)
            return None
        if not handle.can_command:
            self._refuse(robot, what, f"{self.world.user} does not own {robot} (owner: {handle.owner or 'nobody'}); "
                                      f"start the bridge with --request {robot}, or release it to this login")
            return None
        return handle

    def _on_cmd_vel(self, robot: str, msg: Twist) -> None:
        base = self._check_owner(robot, "cmd_vel")
        if base is None:
            return
        try:
            base.twist(float(msg.linear.x), float(msg.angular.z), hold=False)
            self.forwarded[robot] += 1
        except (FabricUserError, ValueError) as exc:
            self._refuse(robot, "cmd_vel", getattr(exc, "reason", str(exc)))

    def _on_joint_command(self, robot: str, msg: JointState) -> None:
        arm = self._check_owner(robot, "joint_command")
        if arm is None:
            return
        names = list(arm.entry.joint_names)
        positions = [float(v) for v in msg.position]
        if msg.name:  # by name, in any order; every joint named once
            if sorted(msg.name) != sorted(names):
                self._refuse(robot, "joint_command", f"names {list(msg.name)} are not {robot}'s joints {names}")
                return
            by_name = dict(zip(msg.name, positions))
            positions = [by_name[n] for n in names]
        try:
            arm.move_joints(positions, wait=False)
            self.forwarded[robot] += 1
        except (FabricUserError, ValueError) as exc:
            self._refuse(robot, "joint_command", getattr(exc, "reason", str(exc)))

    def _report_rejections(self) -> None:
        """The sims' refusals of what this login sent (a lease lost between our look and the sim's) on /rosout."""
        mark = self.world.event_mark()
        for rid in list(self._inputs):
            for ev in self.world.rejections(rid, self._event_mark):
                self._refuse(rid, "a command", f"the sim refused it: {ev.reason}")
        self._event_mark = mark

    # ------------------------------------------------------------------ end
    def close(self) -> None:
        """Stop listening to the world (the node and the world are the caller's to close). Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        for sub in self._subs:
            try:
                sub.undeclare()
            except Exception:
                pass
        self._subs.clear()
        try:
            self._timer.cancel()
        except Exception:
            pass

    def summary(self) -> str:
        """One line: what went out and what came in."""
        return (f"{sum(self.published.values())} messages published on {len(self.published)} topics, "
                f"{sum(self.forwarded.values())} commands forwarded, {sum(self.refused.values())} refused, "
                f"{self.unconverted} not converted")


def spin(bridge: Ros2Bridge) -> None:
    """Run the node until Ctrl-C or SIGTERM (rclpy's signal handlers shut its context down)."""
    try:
        rclpy.spin(bridge.node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
