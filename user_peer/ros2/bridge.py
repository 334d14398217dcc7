"""The ROS 2 bridge: one robofabric login's view of a world, as ROS 2 topics, and its commands from ROS 2.

Out (every robot of the world, followed as sims and robots come and go)::

    /NS/ROBOT/joint_states  sensor_msgs/JointState   from rf/W/robot/ROBOT/joints
    /NS/ROBOT/scan          sensor_msgs/LaserScan    from rf/W/robot/ROBOT/scan     (sensor-data QoS: best effort)
    /NS/ROBOT/sonar         sensor_msgs/LaserScan    from rf/W/robot/ROBOT/sonar    (ranges from the ring's centre)
    /NS/ROBOT/sonar_I       sensor_msgs/Range        each transducer of the ring, while a node listens (ranges.py)
    /NS/ROBOT/odom          nav_msgs/Odometry        from a mobile base's rf/W/robot/ROBOT/pose
    /NS/ROBOT/pose          geometry_msgs/PoseStamped from an arm's pose (its flange)
    /NS/ROBOT/path          nav_msgs/Path            from rf/W/robot/ROBOT/path     (reliable, transient local)
    /NS/map                 nav_msgs/OccupancyGrid   from rf/W/map/map (other maps: /NS/maps/NAME; reliable, transient local)
    /NS/object/ID/pose      geometry_msgs/PoseStamped from rf/W/object/ID/pose/by/*
    /NS/clock               rosgraph_msgs/Clock      the sims' time (the newest header stamp of robot state)
    /NS/tf, /NS/tf_static   tf2_msgs/TFMessage       REP 105's tree under map, the export's (tf.py; tf2_msgs: msgbuild.py)
    /NS/ROBOT/robot_description std_msgs/String      the robot type's URDF (latched; models.py)
    /NS/ROBOT/owner         std_msgs/String          the login that owns the robot, "" when free (latched; owners.py)
    /NS/ROBOT/request_ownership, release_ownership   std_srvs/Trigger services, --drive robots (ownership_services.py)

In (only for the robots named in ``drive``, the ``--drive`` option: a ROS 2 domain has no logins, so by default
the bridge only publishes (:mod:`user_peer.ros2.trust`); and for those, acted on only while this login owns
them, as for any user; a refusal is logged on /rosout and counted)::

    /NS/ROBOT/cmd_vel           geometry_msgs/Twist             -> Base.twist(linear.x, angular.z, hold=False)
                                (TwistStamped with stamped_cmd_vel; not finite or absurd: refused; clamps told)
    /NS/ROBOT/goal_pose, /NS/goal_pose  geometry_msgs/PoseStamped -> Base.plan_to, then Base.follow (goals.py)
    /NS/ROBOT/navigate_to_pose  nav2_msgs/action/NavigateToPose -> the same, with feedback and a result (navigate.py)
    /NS/ROBOT/joint_command     sensor_msgs/JointState          -> Arm.move_joints(positions, wait=False)
    /NS/ROBOT/joint_trajectory  trajectory_msgs/JointTrajectory -> Arm.move_joints(its points at their times, 50 Hz)
    /NS/ROBOT/follow_joint_trajectory  control_msgs/action/FollowJointTrajectory -> the same, feedback, a result

Topic names, frame ids, stamps and values are those of ``export --to ros2``
(:func:`user_peer.openfmt.ros2.ros2_topic`, :class:`~user_peer.openfmt.ros2.SimStamps`,
:func:`~user_peer.openfmt.ros2.ros2_message`): stamps are the sim's time, which /clock carries, so a node
with ``use_sim_time`` sees them near its ``now()``. The frequent streams (joints, scans, odometry, poses) are
built straight into one reused rclpy message per topic (:mod:`user_peer.ros2.direct`, held equal to the
export's conversion by its tests); maps and paths are filled from the export's dicts. Each ``cmd_vel`` is
forwarded once (``hold=False``): the sim's deadman stops a base 0.5 s after the last fresh twist, so a ROS
stream that stops, stops the base, as a ROS user expects of ``cmd_vel``.

Threads: zenoh's callbacks convert and publish (rclpy publishers may be used from any thread), with no lock
per message (a lock guards the creation of publishers, another /clock's order when the sim time moves on);
the rclpy executor runs the command callbacks and a 1 s timer that follows the world's robots. Each
subscription's callbacks run in a Python thread of their own (zenoh's default), one per frequent stream: one
thread for all of them was tried and fell further behind on a loaded machine, where the scheduler shares the
cores per thread (docs/ros2.md, "Where the tail comes from"). Nothing slow runs in those callbacks: the message
types' support is imported at start, not by a stream's first publisher.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any, Callable, Collection

import rclpy
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.type_support import check_for_type_support
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan
from trajectory_msgs.msg import JointTrajectory

from fabric import keys
from fabric.interfaces import JointState as FabricJointState
from fabric.interfaces import Pose, Scan
from fabric.streams import STREAMS
from robots.kinds import facts
from user_peer.catalog import RobotCatalog
from user_peer.errors import FabricUserError
from user_peer.openfmt.frames import base_frame, scan_frame
from user_peer.openfmt.ros2 import (
    SimStamps,
    ros2_message,
    ros2_topic,
    ros_topic,
    scan_period,
    sensor_range_min,
    sim_time_ns,
    sonar_radius,
)
from user_peer.pause import is_pause, pause_words
from user_peer.ros2 import direct
from user_peer.ros2.bumps import BUMP_KINDS, bump_lines
from user_peer.ros2.commands import joint_targets
from user_peer.ros2.fill import fill, message_class
from user_peer.ros2.follow_trajectory import FollowTrajectoryActions
from user_peer.ros2.goals import GoalsIn
from user_peer.ros2.models import ModelsOut
from user_peer.ros2.names import frame_prefix, prefix_headers
from user_peer.ros2.owners import OwnersOut
from user_peer.ros2.ownership_services import OwnershipServices
from user_peer.ros2.pauses import GcPauses
from user_peer.ros2.ranges import RangesOut
from user_peer.ros2.topic_map import MappedNode, TopicMap, is_off
from user_peer.ros2.tf import TfOut
from user_peer.ros2.trajectory import TrajectoryPlayer, timed_points
from user_peer.ros2.twist import base_limits, twist_check
from user_peer.world import World

__all__ = ["Ros2Bridge", "LATCHED", "RELIABLE", "STREAM"]

log = logging.getLogger("robofabric.ros2")

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
STREAM = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
"""Joint states, odometry and poses: reliable, and a history of 100 (1 s of a robot's joints) rather than ROS's
usual 10, so that a reader held up for a moment (a loaded machine) gets late messages instead of losing the
oldest (KEEP_LAST drops what falls out of the writer's history before the reader acknowledged it)."""
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""A map or a path: the latest is kept for late joiners (rviz2 started after the map was built), as the fabric
latches those keys."""

FOLLOW_PERIOD_S = 1.0
"""How often the bridge looks at the world's description for robots that came or went."""

_QOS = {"stream": STREAM, "sensor_data": qos_profile_sensor_data, "latched": LATCHED}
"""The profile of each QoS name of :data:`fabric.streams.ROS2_QOS`."""
_TYPES: dict[str, tuple[type, QoSProfile]] = {
    **{t.name: (message_class(t.type), _QOS[t.qos]) for s in STREAMS for t in s.ros2},
    "map": (OccupancyGrid, LATCHED),
}
"""A topic's last name -> its ROS type and QoS: the robot streams' (fabric.streams.STREAMS) and the map's
(``/maps/NAME``: a map; ``/object/ID/pose``: a pose)."""


@dataclass(frozen=True, slots=True)
class _Route:
    """Where one fabric key goes: its topic and what a message there needs (worked out once per key)."""

    topic: str
    robot: str | None
    cls: type
    qos: QoSProfile
    frame: str = ""  # a scan's or a joint state's frame (under the namespace's prefix)
    range_min: float = 0.0  # a scan's sensor's, from the world description
    offset: float = 0.0  # a sonar ring's radius (its ranges measured from the rim, given from the centre)
    scan_time: float = 0.0  # a scan's period, 1 / the world's scan rate


class _Out:
    """One topic's publisher and the message refilled for each sample (one zenoh subscription feeds a topic)."""

    __slots__ = ("pub", "msg")

    def __init__(self, pub: Any, msg: Any) -> None:
        self.pub, self.msg = pub, msg


class Ros2Bridge:
    """Republish ``world``'s streams on ``node`` and forward its ROS commands; ``close()`` ends it."""

    def __init__(
        self,
        world: World,
        node: Node,
        *,
        namespace: str = "",
        tf_message: type | None = None,
        trace: bool = False,
        drive: Collection[str] = (),
        stamped_cmd_vel: bool = False,
        goal_map: str = "",
        topic_map: TopicMap | None = None,
    ) -> None:
        self.world = world
        self.rcl_node = node  # what rclpy spins
        self.node = node = MappedNode(node, topic_map) if topic_map is not None else node  # --topic-map (topic_map.py)
        self.namespace = namespace
        self.prefix = frame_prefix(namespace)  # every frame id under the namespace (names.py)
        self.drive = frozenset(drive)  # the robots whose command topics it subscribes to; none: it only publishes
        self.stamped_cmd_vel = stamped_cmd_vel  # cmd_vel as geometry_msgs/TwistStamped (Nav2's, ros2_control's)
        self._lock = threading.Lock()  # publishers' creation and removal only; never taken per message
        self._clock_lock = threading.Lock()  # /clock's order, taken when the sim time moves on
        self._outs: dict[str, _Out] = {}  # topic -> its publisher and message
        self._routes: dict[str, _Route | None] = {}  # fabric key -> route (rebuilt with each description)
        self._robot_topics: dict[str, set[str]] = {}  # robot -> its topics (destroyed when it leaves)
        self._inputs: dict[str, list[Any]] = {}  # robot -> its command subscriptions (none unless in drive)
        self._kinds: dict[str, str] = {}  # robot -> kind ("arm", "mobile"), from the world description
        self._stamps = SimStamps()
        self._clock_ns = 0
        self._clock_msg = Clock()
        self._described: Any = None  # the last world description (each sensor's range_min), from follow()
        self.published: Counter[str] = Counter()  # topic -> messages published
        self.forwarded: Counter[str] = Counter()  # robot -> commands forwarded
        self.refused: Counter[str] = Counter()  # robot -> commands refused (not owned, rejected)
        self.paused: Counter[str] = Counter()  # robot -> commands its sim held (a pause: user_peer.pause)
        self.unconverted = 0  # fabric messages with no ROS place (or failed to convert)
        self.trace: list[tuple[str, int, int, int]] | None = [] if trace else None
        """With ``trace``: (key, stamp, entry, published) per message published, the times ``time.time_ns()`` at
        the zenoh callback's entry (decoded) and after ``publish`` returned; ``robofabric bench ros2`` splits the
        added latency with them (kept in memory, written by ``write_trace``)."""
        self.gc_pauses = GcPauses() if trace else None
        self._event_mark = world.event_mark()
        self._subs: list[Any] = []
        self._closed = False
        # under a namespace, its own clock (/NS/clock): two classes' bridges on one domain would interleave two sims'
        # times on one /clock (jumps back of minutes); a class's nodes remap theirs: -r /clock:=/NS/clock
        self._clock_pub = node.create_publisher(Clock, ros_topic("/".join([namespace.strip("/"), "clock"])), RELIABLE)
        # each type's support is imported now, not by the first publisher of that type: that import (the first
        # JointState publisher took 80 ms here, load 17) ran in a zenoh callback under the lock every other
        # stream's first message waits for (a 350 ms stall of all the bridge's callbacks at its start, load 15)
        for cls in {cls for cls, _ in _TYPES.values()}:
            check_for_type_support(cls)
        self.tf = TfOut(node, RobotCatalog(None), namespace=namespace, message=tf_message)
        self.models = ModelsOut(node, namespace)  # /NS/ROBOT/robot_description, latched
        self.ranges = RangesOut(node, namespace, self.prefix)  # /NS/ROBOT/sonar_I, a Range per transducer
        self.owners = OwnersOut(node, namespace)  # /NS/ROBOT/owner, latched
        self.asking = OwnershipServices(node, namespace, world.robot, world.user)  # request/release_ownership
        # joint_trajectory's points sent at their times, in the sim's time (/clock's): a sim slower than the wall
        # clock (a loaded machine) or paused stretches a trajectory as it does a ROS controller's with use_sim_time
        self.trajectories = TrajectoryPlayer(clock=lambda: self._clock_ns / 1e9)
        self.arm_actions = FollowTrajectoryActions(
            self.rcl_node, namespace, self.trajectories, self._check_owner, self._refuse
        )
        self.goals = GoalsIn(node, namespace, RELIABLE, self._check_owner, self._refuse, goal_map)  # goal_pose
        w = world.name
        fab = world.fabric
        self.follow()  # first: the description's sensors (range_min) are known before the first scan
        self.owners.update(list(self._kinds), self.world.ownership.record)
        self._subs = [  # every robot stream with a ROS 2 topic (fabric.streams), a latched one's latest at once
            *(
                fab.subscribe(keys.robot_stream_all(w, s.name), self._on_state, history=s.latched)
                for s in STREAMS
                if s.ros2
            ),
            fab.subscribe(f"{keys.world_root(w)}/map/*", self._on_state, history=True),
            fab.subscribe(keys.object_pose_all(w), self._on_state, history=True),
        ]
        self._timer = node.create_timer(FOLLOW_PERIOD_S, self._tick)
        if not self.tf.available:
            log.warning(
                "no /tf or /tf_static: tf2_msgs is not importable (it is not among the ROS 2 wheels; "
                "build it with: python -m user_peer.ros2.msgbuild)"
            )
        if not self.goals.actions.available and self.drive:
            log.warning(
                "no navigate_to_pose actions: nav2_msgs is not importable (build it with: python -m user_peer.ros2.msgbuild)"
            )
        if not self.arm_actions.available and self.drive:
            log.warning(
                "no follow_joint_trajectory actions: control_msgs is not importable (build it with: python -m user_peer.ros2.msgbuild)"
            )
        if not self.asking.available and self.drive:
            log.warning(
                "no request_ownership/release_ownership services: std_srvs is not importable "
                "(build it with: python -m user_peer.ros2.msgbuild)"
            )

    # ------------------------------------------------------------------ out
    def _route(self, key: str) -> _Route | None:
        """The route of fabric ``key`` (cached until the next description); None when it has no topic."""
        try:
            return self._routes[key]
        except KeyError:
            pass
        parts = key.split("/")
        robot = parts[3] if len(parts) == 5 and parts[2] == "robot" else None
        topic = ros2_topic(key, self._kinds.get(robot or ""), self.namespace)
        if topic is None:
            if robot is None or robot in self._kinds:  # a pose of a robot not yet described: ask again later
                self._routes[key] = None
            return None
        leaf = topic.rsplit("/", 1)[1]
        cls, qos = _TYPES.get(leaf, (OccupancyGrid, LATCHED) if "/maps/" in topic else (PoseStamped, STREAM))
        route = _Route(topic, robot, cls, qos, self.prefix + base_frame(robot) if robot else self.prefix)
        if cls is LaserScan:
            sonar = leaf == "sonar"
            route = _Route(
                topic,
                robot,
                cls,
                qos,
                self.prefix + scan_frame(robot or "", key),
                sensor_range_min(self._described, key),
                (sonar_radius(self._described, key) or 0.0) if sonar else 0.0,
                scan_period(self._described),
            )
        self._routes[key] = route
        return route

    def _out(self, route: _Route) -> _Out | None:
        out = self._outs.get(route.topic)
        if out is not None:
            return out
        with self._lock:
            out = self._outs.get(route.topic)
            if out is None and not self._closed:
                pub = self.node.create_publisher(route.cls, route.topic, route.qos)
                out = self._outs[route.topic] = _Out(pub, None if is_off(pub) else route.cls())
                if route.robot is not None:
                    self._robot_topics.setdefault(route.robot, set()).add(route.topic)
            return out

    def _convert(self, out: _Out, route: _Route, key: str, msg: Any, ns: int) -> Any:
        """The ROS message of ``msg``: the hot streams built in place (:mod:`user_peer.ros2.direct`), the rest
        filled from the export's dict; None when ``msg`` is not what the topic carries."""
        cls = route.cls
        if cls is JointState and isinstance(msg, FabricJointState):
            return direct.joint_state(out.msg, route.frame, msg, ns)
        if cls is LaserScan and isinstance(msg, Scan):
            return direct.laser_scan(out.msg, route.frame, msg, ns, route.range_min, route.offset, route.scan_time)
        if cls is Odometry and isinstance(msg, Pose):
            return direct.odometry(out.msg, route.robot or "", msg, ns, self.prefix)
        if cls is PoseStamped and isinstance(msg, Pose):  # a new one: objects' history and live samples may cross
            return direct.pose_stamped(PoseStamped(), msg, ns, self.prefix)
        converted = ros2_message(key, msg, ns)
        if converted is None or message_class(converted[0]) is not cls:
            return None
        return prefix_headers(fill(cls(), converted[1]), self.prefix)

    def _on_state(self, key: str, msg: Any) -> None:
        """A fabric message: convert it as the MCAP export does and publish it (zenoh's thread)."""
        if self._closed or not self.rcl_node.context.ok():
            return  # stopping (Ctrl-C or SIGTERM shut rclpy's context down before the world closed): nothing to publish on
        entry = time.time_ns() if self.trace is not None else 0
        try:
            route = self._route(key)
            if route is None:
                return
            out = self._out(route)
            if out is None:
                return
            ns = self._stamps(msg)
            if out.msg is not None:  # None: a topic the --topic-map keeps off ROS (nothing built for it)
                ros = self._convert(out, route, key, msg, ns)
                if ros is None:
                    self.unconverted += 1
                    return
                out.pub.publish(ros)
                if self.trace is not None:
                    self.trace.append((key, ns, entry, time.time_ns()))
                self.published[route.topic] += 1
            if route.robot is not None:
                self.tf.on_state(key, msg, ns)
                if route.cls is LaserScan:
                    self.ranges.on_scan(route.robot, key, msg, ns)
                self._tick_clock(sim_time_ns(msg))
        except Exception:  # a message that does not fit must not end the bridge's subscription
            self.unconverted += 1
            log.exception("could not publish %s on ROS 2", key)

    def _tick_clock(self, ns: int) -> None:
        """/clock: the newest sim time seen in robot state, never going back (several sims: the furthest)."""
        if ns <= self._clock_ns:
            return
        with self._clock_lock:
            if ns <= self._clock_ns or self._closed:
                return
            self._clock_ns = ns
            c = self._clock_msg
            c.clock.sec, c.clock.nanosec = ns // 1_000_000_000, ns % 1_000_000_000
            self._clock_pub.publish(c)
        self.published["/clock"] += 1

    # ------------------------------------------------------------------ following the world
    def _tick(self) -> None:
        try:
            self.follow()
            self.owners.update(list(self._kinds), self.world.ownership.record)
            self._report_rejections()
        except Exception:
            log.exception("following the world failed")

    def follow(self) -> None:
        """Give every robot of the world its command topics; drop the topics of robots that left."""
        try:
            self._described = info = self.world.info()
            entries = {r.id: r.kind for r in info.robots}
        except FabricUserError as exc:  # no sim now: keep what we have, the world's tokens tell the rest
            log.debug("no world description now: %s", exc)
            return
        self._kinds.update(entries)
        self._routes = {}  # each key's route again, with this description's kinds and sensors
        self.tf.describe(info)
        self.models.describe(info)
        self.ranges.describe(info)
        for rid, kind in entries.items():
            if rid not in self._inputs:
                self._inputs[rid] = self._command_inputs(rid, kind)
                if rid in self.drive:
                    self.asking.add(rid)
        for rid in [r for r in list(self._inputs) if r not in entries]:
            for sub in self._inputs.pop(rid):
                self.node.destroy_subscription(sub)
            self._kinds.pop(rid, None)
            self.goals.forget(rid)
            self.arm_actions.forget(rid)
            self.asking.forget(rid)
            with self._lock:
                for topic in self._robot_topics.pop(rid, set()):
                    self.node.destroy_publisher(self._outs.pop(topic).pub)
            self.node.get_logger().info(f"{rid} left world {self.world.name}: its topics are gone")

    def _command_inputs(self, rid: str, kind: str) -> list[Any]:
        """The robot's command subscriptions: none for a robot not named in ``drive`` (nothing on the DDS domain
        is heard for it, so nothing is sent in this login's name)."""
        if rid not in self.drive:
            return []
        topic = lambda leaf: ros_topic("/".join([self.namespace.strip("/"), rid, leaf]))  # noqa: E731
        if facts(kind).base:
            cls = TwistStamped if self.stamped_cmd_vel else Twist
            return [
                self.node.create_subscription(cls, topic("cmd_vel"), lambda m, r=rid: self._on_cmd_vel(r, m), RELIABLE),
                self.goals.subscribe(rid),
            ]
        if facts(kind).chain:
            self.arm_actions.serve(rid)  # follow_joint_trajectory
            return [
                self.node.create_subscription(
                    JointState, topic("joint_command"), lambda m, r=rid: self._on_arm(r, "joint_command", m), RELIABLE
                ),
                self.node.create_subscription(
                    JointTrajectory,
                    topic("joint_trajectory"),
                    lambda m, r=rid: self._on_arm(r, "joint_trajectory", m),
                    RELIABLE,
                ),
            ]
        return []

    # ------------------------------------------------------------------ in
    def _refuse(self, robot: str, what: str, why: str) -> None:
        self.refused[robot] += 1
        n = self.refused[robot]
        text = f"refused {what} for {robot} ({n} refused so far): {why}"
        log.warning("%s", text)
        self.node.get_logger().warning(text, throttle_duration_sec=1.0)

    def _check_owner(self, robot: str, what: str, told: Callable[[str], Any] | None = None) -> Any:
        """The robot's handle when this login may command it; else None, the refusal told (and given to ``told``)."""
        try:
            handle = self.world.robot(robot)
            why = (
                ""
                if handle.can_command
                else (
                    f"{self.world.user} does not own {robot} (owner: {handle.owner or 'nobody'}); "
                    f"start the bridge with --request {robot}, or release it to this login"
                )
            )
        except FabricUserError as exc:
            why = exc.reason
        if why:
            self._refuse(robot, what, why)
            if told is not None:
                told(why)
            return None
        return handle

    def _on_cmd_vel(self, robot: str, msg: Any) -> None:
        """A Twist (or a TwistStamped's twist): refused when not finite or absurd, a clamp told (twist.py)."""
        base = self._check_owner(robot, "cmd_vel")
        if base is None:
            return
        twist = getattr(msg, "twist", msg)
        try:
            v, omega = float(twist.linear.x), float(twist.angular.z)
            note = twist_check(v, omega, base_limits(self._described, robot))
            base.twist(v, omega, hold=False)
            self.forwarded[robot] += 1
            if note:
                self.node.get_logger().warning(f"cmd_vel for {robot}: {note}", throttle_duration_sec=1.0)
        except (FabricUserError, ValueError) as exc:
            self._refuse(robot, "cmd_vel", getattr(exc, "reason", str(exc)))

    def _on_arm(self, robot: str, what: str, msg: Any) -> None:
        """A JointState on joint_command (stops a trajectory playing) or a JointTrajectory on joint_trajectory (played)."""
        arm = self._check_owner(robot, what)
        if arm is None:
            return
        names = list(arm.entry.joint_names)
        try:
            if what == "joint_trajectory":  # sent whole, played by the sim (trajectory.py), replacing the one playing
                timed = timed_points(robot, names, msg, arm.entry.lower, arm.entry.upper)
                self.trajectories.play(
                    robot,
                    timed,
                    arm.joints,
                    lambda t: arm.follow_joints(t.times, t.positions, wait=False),
                    lambda exc: self._refuse(robot, what, getattr(exc, "reason", str(exc))),
                )
            else:
                positions = joint_targets(robot, names, list(msg.name), list(msg.position))
                self.trajectories.stop(robot)
                arm.move_joints(positions, wait=False)
            self.forwarded[robot] += 1
        except (FabricUserError, ValueError) as exc:
            self._refuse(robot, what, getattr(exc, "reason", str(exc)))

    def _report_rejections(self) -> None:
        """The sims' refusals of what this login sent (a lease lost between our look and the sim's) and the bumper
        stops of the world's bases (bumps.py) on /rosout."""
        mark = self.world.event_mark()
        for warn, text in bump_lines(
            self.world.event_log.authority_events(self._event_mark, mark, BUMP_KINDS), self.drive
        ):
            log.log(logging.WARNING if warn else logging.INFO, "%s", text)
            ros = self.node.get_logger()
            (ros.warning if warn else ros.info)(text)
        for rid in list(self._inputs):
            for ev in self.world.rejections(rid, self._event_mark):
                if is_pause(ev):  # the sim held its robots: a pause, said as one (not counted as refused)
                    self.paused[rid] += 1
                    log.info("%s", pause_words(rid, ev))
                    self.node.get_logger().info(pause_words(rid, ev), throttle_duration_sec=1.0)
                else:
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
        self.trajectories.close()
        self.arm_actions.close()
        self.goals.close()
        if self.gc_pauses is not None:
            self.gc_pauses.close()
        try:
            self._timer.cancel()
        except Exception:
            pass

    def write_trace(self, path: str) -> None:
        """The trace (``trace=True``), one line a message: ``KEY STAMP_NS ENTRY_NS PUBLISHED_NS``, and one a garbage
        collection: ``gc GENERATION START_NS END_NS``."""
        pauses = self.gc_pauses.pauses if self.gc_pauses is not None else []
        with open(path, "w") as f:
            f.writelines(f"{k} {s} {a} {b}\n" for k, s, a, b in list(self.trace or ()))
            f.writelines(f"gc {g} {a} {b}\n" for g, a, b in list(pauses))

    def summary(self) -> str:
        """One line: what went out and what came in."""
        return (
            f"{sum(self.published.values())} messages published on {len(self.published)} topics "
            f"({self.published['/clock']} on /clock), "
            f"{sum(self.forwarded.values())} commands forwarded, {sum(self.refused.values())} refused, "
            f"{self.unconverted} not converted, {self.tf.sent} /tf messages"
        )


def spin(bridge: Ros2Bridge) -> None:
    """Run the node until Ctrl-C or SIGTERM (rclpy's signal handlers shut its context down)."""
    try:
        rclpy.spin(bridge.rcl_node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
