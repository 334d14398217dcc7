"""Where every robot part is: coordinate frames from fabric messages, for Foxglove's and ROS 2's transform trees.

Frame names follow ROS's REP 105 and robot_state_publisher, so that RViz, tf2, Nav2 and a RobotModel display with
``tf_prefix ID/`` take them as they are: ``map`` is the root, the world's frame (the world's maps are drawn in its
coordinates; a fabric message's ``world`` frame is ``map`` here, :func:`ros_frame`). A mobile base is
``map -> ID/odom -> ID/base_link`` (``map -> ID/odom`` the identity: the sim's poses do not drift; ``ID/odom ->
ID/base_link`` its pose), its LIDAR ``ID/laser`` and its sonar ring's centre ``ID/sonar`` on ``ID/base_link``
(the Reeman URDF's links), its wheels (the URDF's moving links) from its JointState. An arm's frames are its URDF's links under ``ID/``: the root link (``ID/base_link``
on the Meca500) bolted to ``map`` where the arm stands, and each link in its parent link's frame, placed by
forward kinematics from its JointState (fixed links, the flange, too), as robot_state_publisher gives them; its
flange pose (the sim's ``robot/ID/pose``) is the URDF's flange link, so it adds no frame of its own (an arm
whose URDF is not known here gets ``map -> ID/flange`` from it; one whose placement is not known, its links
without ``map -> ID/ROOT``). Scene objects are ``object/ID`` (whoever moved
it: its key is ``rf/W/object/ID/pose/by/USER``). What a robot is (arm or mobile base, its URDF, where an arm
stands) comes from the same robot descriptions the live viewer uses (:class:`user_peer.catalog.RobotCatalog`).

One transform tree, as tf2 and Foxglove require: every frame has one parent and one source (an arm's links come
from its JointState, a mobile base's frames from its pose), and each frame's stamps never go back: a transform
older than the last one written for the same frame (two sims' clocks during a failover, a late sample) is dropped
(counted in ``stale``). An arm's base is bolted down: the same transform from ``map`` every time.
"""

from __future__ import annotations

import math
import threading
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

import numpy as np

from fabric.interfaces import JointState, Pose
from fabric.interfaces.geometry import quaternion_from_yaw
from robots.kinds import facts
from user_peer.arm_geometry import Placement, Shape
from user_peer.catalog import RobotCatalog
from user_peer.geometry import quat_xyzw
from user_peer.openfmt.urdf_joints import MovingJoint, joint_transform, moving_joints
from user_peer.rerun_log import RobotDrawing

__all__ = [
    "Frame",
    "FrameTracker",
    "MAP",
    "FIXED",
    "base_frame",
    "key_owner",
    "ros_frame",
    "scan_frame",
    "yaw_quat_xyzw",
]

MAP = "map"
FIXED = ("/odom", "/laser", "/sonar")
"""The suffixes of a base's frames that never move in their parent: ``map -> ID/odom`` and the sensor mounts
(the live bridge sends them on ``/tf_static`` too)."""
_IDENTITY = (0.0, 0.0, 0.0, 1.0)


def ros_frame(frame: str) -> str:
    """A fabric message's frame as the trees name it: the world's (``world``, or none) is ``map``."""
    return MAP if frame in ("", "world") else frame


def base_frame(rid: str) -> str:
    """A robot's REP 105 base frame, ``ID/base_link`` (a JointState's and an odometry's child frame)."""
    return f"{rid}/base_link"


def scan_frame(rid: str, key: str) -> str:
    """The frame of a robot's Scan on ``key``: ``ID/sonar`` (the ring's centre) for ``.../sonar``, else ``ID/laser``."""
    return f"{rid}/{'sonar' if key.endswith('/sonar') else 'laser'}"


@dataclass(frozen=True, slots=True)
class Frame:
    """A transform: ``child`` expressed in ``parent``; rotation as a quaternion (x, y, z, w)."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]


def yaw_quat_xyzw(yaw: float) -> tuple[float, float, float, float]:
    """The rotation by ``yaw`` about z as an (x, y, z, w) quaternion, the order of Foxglove's and ROS 2's messages."""
    x, y, z, w = quat_xyzw(quaternion_from_yaw(yaw))
    return (x, y, z, w)


def _frame(parent: str, child: str, p: Placement) -> Frame:
    t = np.asarray(p.translation, dtype=float)
    q = np.asarray(p.quat_xyzw, dtype=float)
    return Frame(
        parent, child, (float(t[0]), float(t[1]), float(t[2])), (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
    )


def key_owner(key: str) -> tuple[str, str] | None:
    """("robot", ID) or ("object", ID) for keys ``rf/W/robot/ID/...`` and ``rf/W/object/ID/...``, else None."""
    parts = key.split("/")
    if len(parts) >= 5 and parts[2] in ("robot", "object"):
        return parts[2], parts[3]
    return None


class FrameTracker:
    """Turns JointState and Pose messages into frames; remembers what each robot is."""

    def __init__(self, catalog: RobotCatalog) -> None:
        self.catalog = catalog
        self.robots: dict[str, RobotDrawing] = {}
        self._stamps: dict[str, int] = {}  # child frame -> the newest stamp written for it
        self.stale = 0  # transforms dropped because their frame already had a newer one
        self._urdf_joints: dict[str, dict[str, MovingJoint]] = {}  # a mobile base's type -> its URDF's moving joints
        self._described: set[str] = set()  # robots drawn from the world description (the others are guesses)
        self._lock = threading.Lock()  # robot state comes on several threads (the bridge's zenoh callbacks)

    def robot(self, rid: str, hint: dict) -> RobotDrawing:
        """``rid``'s drawing. A guess (its poses or joints before the world description named it: a scene's, a
        joint-name match, or "mobile" by a pose's hint) gives way to joint names that name the type, and to the
        description once it names ``rid`` (:meth:`describe` says which drawings that changed)."""
        with self._lock:
            info = self.robots.get(rid)
            if (
                info is None
                or (not info.kind and hint)
                or (not info.type and hint.get("joint_names"))
                or (rid not in self._described and self.catalog.describes(rid))
            ):
                info = self.robots[rid] = self.catalog.drawing(rid, hint)
                if self.catalog.describes(rid):
                    self._described.add(rid)
            return info

    def describe(self, info: Any) -> list[str]:
        """The world description (a ``WorldInfo``) from now on: the robots drawn from a guess that it names are
        drawn again from it; the ids whose drawing that changed (their static frames, :meth:`mounts`, may too)."""
        self.catalog.world_info = info
        changed = []
        for rid, old in list(self.robots.items()):
            new = self.robot(rid, {})
            if (new.kind, new.type, new.sonar, tuple(new.lidar_offset)) != (
                old.kind,
                old.type,
                old.sonar,
                tuple(old.lidar_offset),
            ):
                changed.append(rid)
        return changed

    def mounts(self, rid: str) -> list[Frame]:
        """The frames of ``rid`` that never move in their parent (``frames.FIXED``: a base's ``map -> ID/odom``
        and sensor mounts), as its drawing has them now; none for an arm or a robot not seen."""
        info = self.robots.get(rid)
        if info is None or facts(info.kind).chain:
            return []
        return [f for f in self._base(rid, info, None) if f.child.endswith(FIXED)]

    def _base(self, oid: str, info: RobotDrawing, p: Placement | None) -> list[Frame]:
        """A mobile base's (or a robot of unknown kind with a pose) frames; ``p`` its pose (None: the mounts only)."""
        base = base_frame(oid)
        out = [Frame(MAP, f"{oid}/odom", (0.0, 0.0, 0.0), _IDENTITY)]
        if p is not None:
            out.append(_frame(f"{oid}/odom", base, p))
        if facts(info.kind).base:
            out.append(Frame(base, f"{oid}/laser", tuple(float(v) for v in info.lidar_offset), _IDENTITY))  # type: ignore[arg-type]
            if info.sonar is not None:
                cx, cy, h, _r = info.sonar
                out.append(Frame(base, f"{oid}/sonar", (cx, cy, h), _IDENTITY))
        return out

    def frames(self, key: str, msg: Any, stamp_ns: int | None = None) -> list[Frame]:
        """The transforms ``msg`` on ``key`` gives; with ``stamp_ns``, only those not older than their frame's last."""
        out = self._frames(key, msg)
        if stamp_ns is None or not out:
            return out
        fresh = []
        for f in out:
            if self._stamps.get(f.child, stamp_ns) > stamp_ns:
                self.stale += 1
                continue
            self._stamps[f.child] = stamp_ns
            fresh.append(f)
        return fresh

    def _frames(self, key: str, msg: Any) -> list[Frame]:
        owner = key_owner(key)
        if owner is None:
            return []
        what, oid = owner
        leaf = key.split("/")[4]  # rf/W/robot/ID/pose, rf/W/object/ID/pose/by/USER
        if isinstance(msg, Pose) and leaf == "pose":
            p = Placement(np.asarray(msg.position, dtype=float), _xyzw(msg.quaternion))
            if what == "object":
                return [_frame(MAP, f"object/{oid}", p)]
            info = self.robot(oid, {"mobile": True})
            if facts(
                info.kind
            ).chain:  # the flange is the URDF's link, from the joints; a pose only where that is unknown
                return [_frame(MAP, f"{oid}/flange", p)] if info.arm is None else []
            return self._base(oid, info, p)
        if isinstance(msg, JointState) and leaf == "joints" and what == "robot":
            info = self.robot(oid, {"joint_names": msg.names})
            arm = info.arm
            if facts(info.kind).base:
                return self._wheels(oid, info.type, msg)
            if not facts(info.kind).chain or arm is None or len(msg.names) != len(arm.joint_names):
                return []
            placements = arm.link_placements(np.asarray(msg.q, dtype=float))
            at = {name: pl for (name, *_), pl in zip(arm.links, placements)}
            out = [] if info.base is None else [_frame(MAP, f"{oid}/{arm.root_link}", info.base)]
            for (name, parent, _j, _moved), pl in zip(arm.links, placements):
                if parent:  # each link in its parent link's frame, as robot_state_publisher sends it
                    out.append(_frame(f"{oid}/{parent}", f"{oid}/{name}", _relative(at[parent], pl)))
            return out
        return []

    def _wheels(self, rid: str, rtype: str, msg: JointState) -> list[Frame]:
        """A mobile base's moving links (its wheels) by its URDF, each in its parent link's frame, as
        robot_state_publisher places them from the JointState (the URDF's fixed links are the pose's mounts)."""
        if rtype not in self._urdf_joints:
            self._urdf_joints[rtype] = _type_joints(self.catalog, rtype)
        joints = self._urdf_joints[rtype]
        out = []
        for name, q in zip(msg.names, np.asarray(msg.q, dtype=float)):
            j = joints.get(name)
            if j is not None:
                t, r = joint_transform(j, float(q))
                out.append(Frame(f"{rid}/{j.parent}", f"{rid}/{j.child}", t, r))
        return out

    def shapes(self, rid: str) -> list[tuple[str, Shape, Placement]]:
        """(frame, shape, placement in that frame) of a known robot's visual parts."""
        info = self.robots.get(rid)
        if info is None:
            return []
        if facts(info.kind).chain and info.arm is not None:
            frames = [f"{rid}/{n}" for n in info.arm.joint_links]
            out = []
            for shape, joint, local in info.arm.shapes:
                pl = Placement(np.array(local.translation, dtype=float), _xyzw_from_matrix(np.array(local.rotation)))
                out.append((frames[joint] if joint < len(frames) else frames[0], shape, pl))
            return out
        if facts(info.kind).base:
            body = Shape(f"{rid}_body", "cylinder", (info.radius, info.height), color=(*info.color, 255))
            return [
                (
                    base_frame(rid),
                    body,
                    Placement(np.array([0.0, 0.0, info.height / 2.0]), np.array([0.0, 0.0, 0.0, 1.0])),
                )
            ]
        return []


def _type_joints(catalog: RobotCatalog, rtype: str) -> dict[str, MovingJoint]:
    """The moving joints of robot type ``rtype``'s URDF; none where the type or its URDF is not known here."""
    d = catalog.descriptions().get(rtype)
    try:
        return moving_joints(d.urdf_path.read_text()) if d is not None and d.urdf_path is not None else {}
    except (ET.ParseError, OSError, ValueError):
        return {}


def _relative(base: Placement, p: Placement) -> Placement:
    """``p`` (a world placement) expressed in ``base``'s frame: base^-1 * p."""
    rb = _matrix_from_xyzw(np.asarray(base.quat_xyzw, dtype=float))
    rp = _matrix_from_xyzw(np.asarray(p.quat_xyzw, dtype=float))
    t = rb.T @ (np.asarray(p.translation, dtype=float) - np.asarray(base.translation, dtype=float))
    q = _xyzw_from_matrix(rb.T @ rp)
    return Placement(t, q / np.linalg.norm(q))


def _matrix_from_xyzw(q: np.ndarray) -> np.ndarray:
    x, y, z, w = (float(v) for v in q / np.linalg.norm(q))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _xyzw(quat_wxyz: np.ndarray) -> np.ndarray:
    return np.array(quat_xyzw(quat_wxyz))


def _xyzw_from_matrix(r: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) of a rotation matrix (Shepperd's method, numerically safe branch)."""
    t = float(np.trace(r))
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        return np.array([(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s])
    i = int(np.argmax(np.diag(r)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k]) * 2
    q = np.zeros(4)
    q[i] = 0.25 * s
    q[j] = (r[j, i] + r[i, j]) / s
    q[k] = (r[k, i] + r[i, k]) / s
    q[3] = (r[k, j] - r[j, k]) / s
    return q
