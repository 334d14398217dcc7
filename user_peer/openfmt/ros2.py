"""ROS 2's MCAP (what rosbag2's MCAP storage reads): CDR messages, ``ros2msg`` schemas, profile ``ros2``.

=================  ==========================  ======================================
fabric             ROS 2 topic                 type
=================  ==========================  ======================================
JointState         ``/KEY``                    ``sensor_msgs/msg/JointState``
Scan               ``/KEY``                    ``sensor_msgs/msg/LaserScan`` (``ID/lidar``)
Pose               ``/KEY``                    ``geometry_msgs/msg/PoseStamped``
OccupancyGrid      ``/KEY``                    ``nav_msgs/msg/OccupancyGrid`` (255 -> -1)
Path               ``/KEY``                    ``nav_msgs/msg/Path``
poses and arm FK   ``/tf``                     ``tf2_msgs/msg/TFMessage``
anything else      ``/KEY``                    ``std_msgs/msg/String`` holding the JSON
=================  ==========================  ======================================

A LaserScan's ``range_min`` is its sensor's in the world description (0.0 in a recording without one), and a
missing echo (the fabric's ``range_max``) is +inf, as REP 117 says. The sonar ring's ranges are measured from
the ring's rim and its frame ``ID/sonar`` is at the ring's centre: the ring's radius is added to the ranges and
the limits (from the world description, else the robot's own), so that every range is true in that frame.

Topic names are the fabric keys with a leading slash; characters ROS names do not allow become
``_``. Written with ``mcap-ros2-support``'s writer.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path as FsPath
from typing import Any

import numpy as np
from mcap_ros2.writer import Writer as Ros2McapWriter

from fabric.interfaces import JointState, OccupancyGrid, Path, plain_view, Pose, Scan, WorldInfo
from user_peer.catalog import RobotCatalog
from user_peer.openfmt.foxglove import msg_time_ns
from user_peer.openfmt.frames import WORLD, FrameTracker, key_owner, yaw_quat_xyzw
from user_peer.openfmt.ros2_msgdefs import definition

__all__ = ["Ros2Writer", "ros2_message", "ros_topic", "scan_ranges", "sensor_range_min", "sonar_radius", "TF_TOPIC"]

TF_TOPIC = "/tf"
_BAD = re.compile(r"[^A-Za-z0-9_/]")


def ros_topic(key: str) -> str:
    """``rf/demo/robot/arm1/joints`` -> ``/rf/demo/robot/arm1/joints`` (invalid characters -> ``_``)."""
    parts = [_BAD.sub("_", p) for p in key.split("/") if p]
    parts = [f"_{p}" if p[0].isdigit() else p for p in parts]
    return "/" + "/".join(parts)


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


def ros2_message(key: str, msg: Any, stamp_ns: int, *, range_min: float = 0.0, range_offset: float = 0.0) -> tuple[str, dict] | None:
    """(ROS 2 type name, the message as a dict of its fields) for fabric ``msg`` on ``key``, stamped
    ``stamp_ns``; None for a message ROS 2 has no place for. The one conversion of the MCAP export and the
    live bridge (:mod:`user_peer.ros2`), so that both give the same frames, stamps and values. ``range_min``:
    a scan's sensor's (:func:`sensor_range_min`), which the fabric's Scan does not carry; ``range_offset``: added
    to every range and to the limits, so that a sonar's ranges, measured from the ring's rim, are true in its
    frame ``ID/sonar`` at the ring's centre (the ring's radius, :func:`sonar_radius`)."""
    t = stamp_ns
    owner = key_owner(key)
    rid = owner[1] if owner else WORLD
    if isinstance(msg, JointState):
        return ("sensor_msgs/msg/JointState",
                {"header": _header(t, rid), "name": list(msg.names), "position": [float(v) for v in msg.q],
                 "velocity": [float(v) for v in msg.dq], "effort": []})
    if isinstance(msg, Scan):
        n = int(msg.ranges_mm.shape[0])
        frame = f"{rid}/{'sonar' if key.endswith('/sonar') else 'lidar'}"
        return ("sensor_msgs/msg/LaserScan",
                {"header": _header(t, frame), "angle_min": float(msg.angle_min),
                 "angle_max": float(msg.angle_min + msg.angle_increment * max(n - 1, 0)),
                 "angle_increment": float(msg.angle_increment), "time_increment": 0.0, "scan_time": 0.0,
                 "range_min": float(range_min) + range_offset, "range_max": float(msg.range_max) + range_offset,
                 "ranges": scan_ranges(msg, range_offset),
                 "intensities": []})
    if isinstance(msg, OccupancyGrid):
        h, w = msg.cells.shape
        ox, oy, oth = (float(v) for v in msg.origin)
        return ("nav_msgs/msg/OccupancyGrid",
                {"header": _header(t, WORLD),
                 "info": {"map_load_time": _time(t), "resolution": float(msg.resolution), "width": int(w), "height": int(h),
                          "origin": _pose((ox, oy, 0.0), yaw_quat_xyzw(oth))},
                 "data": grid_data(msg.cells)})
    if isinstance(msg, Path):
        frame = msg.frame or WORLD
        poses = [
            {"header": _header(t, frame), "pose": _pose((float(x), float(y), 0.0), yaw_quat_xyzw(float(th)))}
            for x, y, th in zip(msg.x, msg.y, msg.theta)
        ]
        return "nav_msgs/msg/Path", {"header": _header(t, frame), "poses": poses}
    if isinstance(msg, Pose):
        q = msg.quaternion
        return ("geometry_msgs/msg/PoseStamped",
                {"header": _header(t, msg.frame or WORLD), "pose": _pose(msg.position, (q[1], q[2], q[3], q[0]))})
    plain = plain_view(msg) if hasattr(type(msg), "SPEC") else None
    if plain is None or not all(_finite(v) for v in _leaves(plain)):
        return None
    return "std_msgs/msg/String", {"data": json.dumps(plain)}


class Ros2Writer:
    """Write fabric messages as a ROS 2 MCAP bag; ``close()`` finishes it."""

    def __init__(self, path: FsPath, *, catalog: RobotCatalog | None = None, scene: str | None = None) -> None:
        self.path = FsPath(path)
        self._f = open(self.path, "wb")
        self._w = Ros2McapWriter(self._f)
        self._schemas: dict[str, Any] = {}
        self._tf_pub = 0
        self.frames = FrameTracker(catalog or RobotCatalog(None, scene=scene))
        self.written = 0
        self.skipped = 0
        self._closed = False

    def _schema(self, type_name: str) -> Any:
        s = self._schemas.get(type_name)
        if s is None:
            s = self._schemas[type_name] = self._w.register_msgdef(type_name, definition(type_name))
        return s

    def _put(self, topic: str, type_name: str, message: dict, log_time: int, pub: int) -> None:
        self._w.write_message(topic, self._schema(type_name), message, log_time=log_time, publish_time=pub)
        self.written += 1

    def write(self, key: str, msg: Any, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        pub = int(publish_time_ns if publish_time_ns is not None else log_time_ns)
        t = msg_time_ns(msg, log_time_ns)
        topic = ros_topic(key)
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
        scan = isinstance(msg, Scan)
        converted = ros2_message(key, msg, t, range_min=self._range_min(key) if scan else 0.0,
                                 range_offset=self._sonar_radius(key) if scan else 0.0)
        if converted is None:
            self.skipped += 1
            return
        self._put(topic, converted[0], converted[1], log_time_ns, pub)

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

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._w.finish()
        finally:
            self._f.close()

    def __enter__(self) -> "Ros2Writer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
