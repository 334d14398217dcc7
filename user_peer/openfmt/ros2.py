"""ROS 2's MCAP (what rosbag2's MCAP storage reads): CDR messages, ``ros2msg`` schemas, profile ``ros2``.

=================  ===========================  ======================================
fabric             ROS 2 topic                  type
=================  ===========================  ======================================
JointState         ``/ID/joint_states``         ``sensor_msgs/msg/JointState`` (frame ``ID/base_link``)
Scan               ``/ID/scan``, ``/ID/sonar``  ``sensor_msgs/msg/LaserScan`` (``ID/laser``, ``ID/sonar``)
a base's Pose      ``/ID/odom``                 ``nav_msgs/msg/Odometry`` (``ID/odom``, child ``ID/base_link``)
an arm's Pose      ``/ID/pose``                 ``geometry_msgs/msg/PoseStamped`` (the flange)
OccupancyGrid      ``/map``, ``/maps/NAME``     ``nav_msgs/msg/OccupancyGrid`` (255 -> -1)
Path               ``/ID/path``                 ``nav_msgs/msg/Path``
an object's Pose   ``/object/ID/pose``          ``geometry_msgs/msg/PoseStamped``
poses and arm FK   ``/tf``                      ``tf2_msgs/msg/TFMessage``
fixed frames       ``/tf_static``               ``tf2_msgs/msg/TFMessage`` (the sonar transducers)
a sonar's Scan     ``/ID/sonar_I``              ``sensor_msgs/msg/Range`` per transducer (``ID/sonar_I``)
robot state        ``/clock``                   ``rosgraph_msgs/msg/Clock`` (the sim's time, when it moves on)
anything else      ``/KEY``                     ``std_msgs/msg/String`` holding the JSON
=================  ===========================  ======================================

The topic names (:func:`ros2_topic`) and the header stamps (:class:`SimStamps`: the sim's time) are the live
bridge's (:mod:`user_peer.ros2`), so one rviz2 configuration serves a recording and the live world; a key
without such a name is named after itself (``rf/W/own/ID`` -> ``/rf/W/own/ID``, :func:`ros_topic`), characters
ROS names do not allow becoming ``_``.

A LaserScan's ``range_min`` is its sensor's in the world description (0.0 in a recording without one), and a
missing echo (the fabric's ``range_max``) is +inf, as REP 117 says. The sonar ring's ranges are measured from
the ring's rim and its frame ``ID/sonar`` is at the ring's centre: the ring's radius is added to the ranges and
the limits (from the world description, else the robot's own), so that every range is true in that frame.
Each transducer is also a ``Range`` in its own frame on the rim (:mod:`user_peer.openfmt.ros2_ranges`, the
live bridge's), its angle the world description's (else the scan's), the frames on ``/tf_static`` once each.

Written with ``mcap-ros2-support``'s writer.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path as FsPath
from typing import Any

import numpy as np
from mcap_ros2.writer import Writer as Ros2McapWriter

from fabric import streams
from fabric.recording.mcap_file import McapFile
from fabric.interfaces import JointState, OccupancyGrid, Path, Pose, Scan, WorldInfo
from robots.kinds import facts
from user_peer.catalog import RobotCatalog
from user_peer.message_schema import plain_view
from user_peer.openfmt.frames import (
    MAP,
    Frame,
    FrameTracker,
    base_frame,
    key_owner,
    ros_frame,
    scan_frame,
    yaw_quat_xyzw,
)
from user_peer.openfmt.ros2_msgdefs import definition
from user_peer.openfmt.ros2_ranges import BEAM_HALF_WIDTH, ULTRASOUND, range_value, transducer_frames, transducer_name

__all__ = [
    "Ros2Writer",
    "SimStamps",
    "ODOM_COVARIANCE",
    "odometry_fields",
    "scan_period",
    "ros2_message",
    "ros2_topic",
    "to_body",
    "sim_time_ns",
    "ros_topic",
    "scan_ranges",
    "sensor_range_min",
    "sonar_radius",
    "TF_TOPIC",
]

TF_TOPIC = "/tf"
CLOCK_TOPIC = "/clock"
_BAD = re.compile(r"[^A-Za-z0-9_/]")


def ros_topic(key: str) -> str:
    """``rf/demo/robot/arm1/joints`` -> ``/rf/demo/robot/arm1/joints`` (invalid characters -> ``_``)."""
    parts = [_BAD.sub("_", p) for p in key.split("/") if p]
    parts = [f"_{p}" if p[0].isdigit() else p for p in parts]
    return "/" + "/".join(parts)


def ros2_topic(key: str, kind: str | None = None, namespace: str = "") -> str | None:
    """The ROS 2 topic of fabric ``key``, the same in the live bridge and in ``export --to ros2``, so that one
    rviz2 configuration serves both: ``/ROBOT/joint_states``, ``/ROBOT/scan``, ``/ROBOT/sonar``,
    ``/ROBOT/path``, a pose as ``/ROBOT/odom`` (``kind`` "mobile": Odometry) or ``/ROBOT/pose`` (an arm's
    flange), ``/map`` (other maps ``/maps/NAME``), ``/object/ID/pose``; under ``/NAMESPACE`` when given (a robot
    stream's topic: :func:`fabric.streams.ros2_topic`). None for a key with no such place (a pose of a robot of
    unknown kind; the export names the others after the key)."""
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    parts = key.split("/")  # rf/W/robot/ID/stream, rf/W/map/NAME, rf/W/object/ID/pose/by/USER
    if len(parts) == 5 and parts[2] == "robot":
        topic = streams.ros2_topic(parts[4], kind)
        return ros_topic(f"{ns}/{parts[3]}/{topic.name}") if topic is not None else None
    if len(parts) == 4 and parts[2] == "map":
        return ros_topic(f"{ns}/map" if parts[3] == "map" else f"{ns}/maps/{parts[3]}")
    if len(parts) >= 5 and parts[2] == "object" and parts[4] == "pose":
        return ros_topic(f"{ns}/object/{parts[3]}/pose")
    return None


def _time(ns: int) -> dict:
    return {"sec": int(ns // 1_000_000_000), "nanosec": int(ns % 1_000_000_000)}


def _header(ns: int, frame: str) -> dict:
    return {"stamp": _time(ns), "frame_id": frame}


def _pose(t: Any, q_xyzw: Any) -> dict:
    return {
        "position": {"x": float(t[0]), "y": float(t[1]), "z": float(t[2])},
        "orientation": {"x": float(q_xyzw[0]), "y": float(q_xyzw[1]), "z": float(q_xyzw[2]), "w": float(q_xyzw[3])},
    }


def grid_data(cells: np.ndarray) -> list[int]:
    """Fabric cells (0..100, 255 unknown) as ROS occupancy values (0..100, -1 unknown), row-major."""
    a = np.asarray(cells, dtype=np.int16).ravel()
    return np.where(a == 255, -1, a).astype(np.int8).tolist()


ODOM_VARIANCE = 1e-6
"""The variance on each axis of a base's odometry (pose and twist): the sim's pose and velocities are its physics'
own state, with no noise (the sim adds noise to ranges only, ``LidarInfo``/``SonarInfo.noise_std``), so this is a
floor, 1 mm (1 mrad) standard deviation, not a model of error: never zero, which robot_localization replaces and
other tools read as "not set"."""
ODOM_COVARIANCE: tuple[float, ...] = tuple(ODOM_VARIANCE if i % 7 == 0 else 0.0 for i in range(36))
"""A 6x6 row-major covariance (x, y, z, roll, pitch, yaw), diagonal: an Odometry's pose and twist covariance."""


def scan_period(world_info: WorldInfo | None) -> float:
    """A LaserScan's ``scan_time``: the seconds between two scans of one sensor, 1 / the world's scan rate
    (``WorldInfo.rates["scan"]``, which the LIDAR and the sonar ring share); 0.0 (ROS's "not known") when the
    description does not say."""
    rate = (world_info.rates or {}).get("scan") if world_info is not None else None
    try:
        return 1.0 / float(rate) if rate and float(rate) > 0 else 0.0
    except (TypeError, ValueError):
        return 0.0


MISS_TOLERANCE_M = 5e-4
"""A range within this of ``range_max`` is a missing echo: the sim reads a ray that hit nothing as ``range_max``,
sent in whole millimetres."""


def sensor_range_min(world_info: WorldInfo | None, key: str) -> float:
    """The ``range_min`` the world description gives the sensor whose scan travels on ``key`` (``.../scan``:
    the LIDAR, ``.../sonar``: the sonar ring); 0.0 when the description does not say."""
    owner = key_owner(key)
    if world_info is None or owner is None or owner[0] != "robot":
        return 0.0
    robot = next((r for r in world_info.robots if r.id == owner[1]), None)
    sensor = None if robot is None else (robot.sonar if key.endswith("/sonar") else robot.lidar)
    return float(sensor.range_min) if sensor is not None else 0.0


def sonar_radius(world_info: WorldInfo | None, key: str) -> float | None:
    """The radius of the sonar ring whose ranges travel on ``key`` (``.../sonar``), from the world description;
    None when it is not a sonar key or the description does not say."""
    owner = key_owner(key)
    if world_info is None or owner is None or owner[0] != "robot" or not key.endswith("/sonar"):
        return None
    robot = next((r for r in world_info.robots if r.id == owner[1]), None)
    return float(robot.sonar.radius) if robot is not None and robot.sonar is not None else None


def scan_ranges(msg: Scan, offset: float = 0.0) -> list[float]:
    """The ranges of a LaserScan: a missing echo (the fabric's ``range_max``) is +inf, as REP 117 says; ``offset``
    added to the others (a sonar's ranges, measured from the ring's rim, made ranges from its centre)."""
    r = np.asarray(msg.ranges, dtype=np.float64)
    return np.where(r >= float(msg.range_max) - MISS_TOLERANCE_M, np.inf, r + offset).tolist()


def sim_time_ns(msg: Any) -> int:
    """A fabric message's sim time (its header's ``stamp``, seconds) in ns; 0 when it has none."""
    stamp = getattr(getattr(msg, "header", None), "stamp", 0.0) or 0.0
    return int(round(float(stamp) * 1e9)) if stamp > 0 else 0


class SimStamps:
    """The stamp a ROS 2 message gets, live and in the export alike: the sim's time (the fabric header's
    ``stamp``), which ``/clock`` carries, so that a node with ``use_sim_time`` (rviz2, Nav2, tf2's buffer) finds
    stamps near its ``now()``. A message without a sim time (a map, a path or an object moved by a user)
    gets the newest sim time seen so far (0 before any: ROS's "the latest" for tf lookups), never the wall
    clock, whose stamps would be decades ahead of /clock's. ``newest`` is /clock's value."""

    def __init__(self) -> None:
        self.newest = 0

    def __call__(self, msg: Any) -> int:
        ns = sim_time_ns(msg)
        if ns > 0:
            if ns > self.newest:
                self.newest = ns
            return ns
        return self.newest


def to_body(q_wxyz: Any, v: Any) -> tuple[float, float, float]:
    """World vector ``v`` in the frame turned by unit quaternion ``q_wxyz`` (R^T v), in plain floats: the
    bridge turns every odometry twist with it, where numpy's small-array calls cost more than the arithmetic."""
    w, x, y, z = (float(c) for c in q_wxyz)
    a, b, c = (float(c) for c in v)
    return (
        (1 - 2 * (y * y + z * z)) * a + 2 * (x * y + z * w) * b + 2 * (x * z - y * w) * c,
        2 * (x * y - z * w) * a + (1 - 2 * (x * x + z * z)) * b + 2 * (y * z + x * w) * c,
        2 * (x * z + y * w) * a + 2 * (y * z - x * w) * b + (1 - 2 * (x * x + y * y)) * c,
    )


def odometry_fields(robot: str, msg: Pose, stamp_ns: int) -> dict:
    """A mobile base's pose as ``nav_msgs/Odometry``, as REP 105 names it: the pose in ``ID/odom`` (the world's
    coordinates: ``map -> ID/odom`` is the identity), child frame ``ID/base_link``, the twist turned from the world
    frame (the sim's velocities) into the base's."""
    q = msg.quaternion
    v, w = to_body(q, msg.linear), to_body(q, msg.angular)
    vec = lambda a: {"x": a[0], "y": a[1], "z": a[2]}  # noqa: E731
    return {
        "header": _header(stamp_ns, f"{robot}/odom"),
        "child_frame_id": base_frame(robot),
        "pose": {"pose": _pose(msg.position, (q[1], q[2], q[3], q[0])), "covariance": list(ODOM_COVARIANCE)},
        "twist": {"twist": {"linear": vec(v), "angular": vec(w)}, "covariance": list(ODOM_COVARIANCE)},
    }


def ros2_message(
    key: str,
    msg: Any,
    stamp_ns: int,
    *,
    range_min: float = 0.0,
    range_offset: float = 0.0,
    kind: str | None = None,
    scan_time: float = 0.0,
) -> tuple[str, dict] | None:
    """(ROS 2 type name, the message as a dict of its fields) for fabric ``msg`` on ``key``, stamped
    ``stamp_ns``; None for a message ROS 2 has no place for. The one conversion of the MCAP export and the
    live bridge (:mod:`user_peer.ros2`), so that both give the same frames, stamps and values. ``range_min``:
    a scan's sensor's (:func:`sensor_range_min`), which the fabric's Scan does not carry; ``range_offset``: added
    to every range and to the limits, so that a sonar's ranges, measured from the ring's rim, are true in its
    frame ``ID/sonar`` at the ring's centre (the ring's radius, :func:`sonar_radius`); ``kind``: the robot's
    ("mobile": its pose is Odometry, :func:`odometry_fields`); ``scan_time``: a scan's, :func:`scan_period`. A
    scan's ``time_increment`` is 0: the sim casts all of a scan's rays at one instant of its time (the header's
    stamp), so a node that projects it (laser_geometry) has no motion between rays to undo."""
    t = stamp_ns
    owner = key_owner(key)
    rid = owner[1] if owner else MAP
    if isinstance(msg, JointState):
        return (
            "sensor_msgs/msg/JointState",
            {
                "header": _header(t, base_frame(rid)),
                "name": list(msg.names),
                "position": [float(v) for v in msg.q],
                "velocity": [float(v) for v in msg.dq],
                "effort": [],
            },
        )
    if isinstance(msg, Scan):
        n = int(msg.ranges_mm.shape[0])
        frame = scan_frame(rid, key)
        return (
            "sensor_msgs/msg/LaserScan",
            {
                "header": _header(t, frame),
                "angle_min": float(msg.angle_min),
                "angle_max": float(msg.angle_min + msg.angle_increment * max(n - 1, 0)),
                "angle_increment": float(msg.angle_increment),
                "time_increment": 0.0,
                "scan_time": float(scan_time),
                "range_min": float(range_min) + range_offset,
                "range_max": float(msg.range_max) + range_offset,
                "ranges": scan_ranges(msg, range_offset),
                "intensities": [],
            },
        )
    if isinstance(msg, OccupancyGrid):
        h, w = msg.cells.shape
        ox, oy, oth = (float(v) for v in msg.origin)
        return (
            "nav_msgs/msg/OccupancyGrid",
            {
                "header": _header(t, MAP),
                "info": {
                    "map_load_time": _time(t),
                    "resolution": float(msg.resolution),
                    "width": int(w),
                    "height": int(h),
                    "origin": _pose((ox, oy, 0.0), yaw_quat_xyzw(oth)),
                },
                "data": grid_data(msg.cells),
            },
        )
    if isinstance(msg, Path):
        frame = ros_frame(msg.frame)
        poses = [
            {"header": _header(t, frame), "pose": _pose((float(x), float(y), 0.0), yaw_quat_xyzw(float(th)))}
            for x, y, th in zip(msg.x, msg.y, msg.theta)
        ]
        return "nav_msgs/msg/Path", {"header": _header(t, frame), "poses": poses}
    if isinstance(msg, Pose) and facts(kind).base and owner is not None and owner[0] == "robot":
        return "nav_msgs/msg/Odometry", odometry_fields(rid, msg, t)
    if isinstance(msg, Pose):
        q = msg.quaternion
        return (
            "geometry_msgs/msg/PoseStamped",
            {"header": _header(t, ros_frame(msg.frame)), "pose": _pose(msg.position, (q[1], q[2], q[3], q[0]))},
        )
    plain = plain_view(msg) if hasattr(type(msg), "SPEC") else None
    if plain is None or not all(_finite(v) for v in _leaves(plain)):
        return None
    return "std_msgs/msg/String", {"data": json.dumps(plain)}


class Ros2Writer(McapFile):
    """Write fabric messages as a ROS 2 MCAP bag; ``close()`` finishes it."""

    def __init__(self, path: FsPath, *, catalog: RobotCatalog | None = None, scene: str | None = None) -> None:
        super().__init__(path, Ros2McapWriter)  # mcap_ros2's writer starts its file itself (profile ros2)
        self._schemas: dict[str, Any] = {}
        self._tf_pub = 0
        self._stamps = SimStamps()  # header stamps: the sim's time, as the live bridge's (docs/ros2.md, "Stamps")
        self.frames = FrameTracker(catalog or RobotCatalog(None, scene=scene))
        self._static: dict[str, Frame] = {}  # /tf_static's frames by child: the map root, each ring's transducers
        self.written = 0
        self.skipped = 0

    def _schema(self, type_name: str) -> Any:
        s = self._schemas.get(type_name)
        if s is None:
            s = self._schemas[type_name] = self.writer.register_msgdef(type_name, definition(type_name))
        return s

    def _put(self, topic: str, type_name: str, message: dict, log_time: int, pub: int) -> None:
        self.writer.write_message(topic, self._schema(type_name), message, log_time=log_time, publish_time=pub)
        self.written += 1

    def write(self, key: str, msg: Any, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        pub = int(publish_time_ns if publish_time_ns is not None else log_time_ns)
        clock = self._stamps.newest
        t = self._stamps(msg)
        if self._stamps.newest > clock and (key_owner(key) or ("",))[0] == "robot":  # /clock, as the live bridge's
            self._put(CLOCK_TOPIC, "rosgraph_msgs/msg/Clock", {"clock": _time(self._stamps.newest)}, log_time_ns, pub)
        frames = self.frames.frames(key, msg, t)
        if frames:
            tfs = [
                {
                    "header": _header(t, f.parent),
                    "child_frame_id": f.child,
                    "transform": {
                        "translation": {"x": f.translation[0], "y": f.translation[1], "z": f.translation[2]},
                        "rotation": {"x": f.rotation[0], "y": f.rotation[1], "z": f.rotation[2], "w": f.rotation[3]},
                    },
                }
                for f in frames
            ]
            self._tf_pub = max(self._tf_pub, pub)  # /tf's publish times never go back (it merges every robot's keys)
            self._put(TF_TOPIC, "tf2_msgs/msg/TFMessage", {"transforms": tfs}, log_time_ns, self._tf_pub)
            self._put_static([], t, log_time_ns)
        scan = isinstance(msg, Scan)
        kind = self._kind(key, msg)
        converted = ros2_message(
            key,
            msg,
            t,
            range_min=self._range_min(key) if scan else 0.0,
            range_offset=self._sonar_radius(key) if scan else 0.0,
            kind=kind,
            scan_time=scan_period(self.frames.catalog.world_info) if scan else 0.0,
        )
        if converted is None:
            self.skipped += 1
            return
        self._put(ros2_topic(key, kind) or ros_topic(key), converted[0], converted[1], log_time_ns, pub)
        if scan and key.endswith("/sonar") and (key_owner(key) or ("",))[0] == "robot":
            self._ranges(key, msg, t, log_time_ns, pub)

    def _put_static(self, frames: list[Frame], t: int, log_time: int) -> None:
        """``/tf_static`` again, all its frames in one message (as tf2's broadcaster sends them), when ``frames``
        holds one it has not sent."""
        new = [f for f in frames if self._static.get(f.child) != f]
        if not new:
            return
        self._static.update((f.child, f) for f in new)
        tfs = [
            {
                "header": _header(t, f.parent),
                "child_frame_id": f.child,
                "transform": {
                    "translation": dict(zip("xyz", f.translation)),
                    "rotation": dict(zip("xyzw", f.rotation)),
                },
            }
            for f in self._static.values()
        ]
        self._put("/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": tfs}, log_time, log_time)

    def _ranges(self, key: str, msg: Scan, t: int, log_time: int, pub: int) -> None:
        """A ring's Scan as one ``sensor_msgs/Range`` per transducer, their frames on /tf_static (the live bridge's)."""
        rid = key.split("/")[3]
        info = self.frames.catalog.world_info
        robot = None if info is None else next((r for r in info.robots if r.id == rid), None)
        sonar = None if robot is None else robot.sonar
        ranges = np.asarray(msg.ranges, dtype=np.float64).tolist()
        angles = (
            sonar.angles
            if sonar is not None and len(sonar.angles) == len(ranges)
            else [msg.angle_min + i * msg.angle_increment for i in range(len(ranges))]
        )
        self._put_static(transducer_frames(rid, angles, self._sonar_radius(key)), t, log_time)
        miss = float(msg.range_max) - MISS_TOLERANCE_M
        lo = float(sonar.range_min) if sonar is not None else 0.0
        for i, r in enumerate(ranges):
            self._put(
                ros_topic(f"{rid}/{transducer_name(i)}"),
                "sensor_msgs/msg/Range",
                {
                    "header": _header(t, f"{rid}/{transducer_name(i)}"),
                    "radiation_type": ULTRASOUND,
                    "field_of_view": 2 * BEAM_HALF_WIDTH,
                    "min_range": lo,
                    "max_range": float(msg.range_max),
                    "range": range_value(r, miss),
                    "variance": 0.0,
                },
                log_time,
                pub,
            )

    def _kind(self, key: str, msg: Any) -> str | None:
        """A robot's kind ("arm", "mobile") as the frame tree knows it (a pose alone: a mobile base), else None."""
        owner = key_owner(key)
        if owner is None or owner[0] != "robot" or not isinstance(msg, Pose):
            return None
        return self.frames.robot(owner[1], {"mobile": True}).kind or None

    def _range_min(self, key: str) -> float:
        return sensor_range_min(self.frames.catalog.world_info, key)

    def _sonar_radius(self, key: str) -> float:
        """The ring's radius from the recorded description, else from the robot's own description (the catalog's)."""
        r = sonar_radius(self.frames.catalog.world_info, key)
        if r is None and key.endswith("/sonar"):
            owner = key_owner(key)
            info = self.frames.robots.get(owner[1]) if owner else None
            r = float(info.sonar[3]) if info is not None and info.sonar is not None else None
        return r or 0.0


def _leaves(x: Any):
    if isinstance(x, dict):
        for v in x.values():
            yield from _leaves(v)
    elif isinstance(x, list):
        for v in x:
            yield from _leaves(v)
    else:
        yield x


def _finite(v: Any) -> bool:
    return not isinstance(v, float) or math.isfinite(v)
