"""Where every robot part is: coordinate frames from fabric messages, for Foxglove's and ROS 2's transform trees.

Frame names: ``world`` is the root; a robot's base is its id (``arm1``, ``base1``); an arm's joint
frames are ``ID/JOINT`` (placed by forward kinematics from its JointState, relative to the base);
an arm's flange (the sim's ``robot/ID/pose``, a world pose) is ``ID/flange``, a child of the base
``ID``; a mobile robot's LIDAR and sonar ring are ``ID/lidar`` and ``ID/sonar``; scene objects are
``object/ID`` (whoever moved it: its key is ``rf/W/object/ID/pose/by/USER``). What a robot is (arm or
mobile base, its URDF, where an arm stands) comes from the same robot descriptions the live viewer
uses (:class:`user_peer.catalog.RobotCatalog`).

One transform tree, as tf2 and Foxglove require: every frame has one parent and one source (an
arm's base and joints come from its JointState, its flange from its pose, a mobile base from its
pose), and each frame's stamps never go back: a transform older than the last one written for the
same frame (two sims' clocks during a failover, a late sample) is dropped (counted in ``stale``).
An arm's base is bolted down: the same transform from ``world`` every time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fabric.interfaces import JointState, Pose
from fabric.interfaces.geometry import quaternion_from_yaw
from user_peer.arm_geometry import Placement, Shape
from user_peer.catalog import RobotCatalog
from user_peer.geometry import quat_xyzw
from user_peer.rerun_log import RobotDrawing

__all__ = ["Frame", "FrameTracker", "WORLD", "MAP", "MAP_ROOT", "key_owner", "yaw_quat_xyzw"]

WORLD = "world"
MAP = "map"


@dataclass(frozen=True, slots=True)
class Frame:
    """A transform: ``child`` expressed in ``parent``; rotation as a quaternion (x, y, z, w)."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]


MAP_ROOT = Frame(MAP, WORLD, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
"""``map -> world``, the identity, for ROS 2's trees (the bridge's and ``export --to ros2``'s ``/tf_static``): the
world's frame is REP 105's fixed ``map`` frame, in the same coordinates (the world's maps are drawn in them)."""


def yaw_quat_xyzw(yaw: float) -> tuple[float, float, float, float]:
    """The rotation by ``yaw`` about z as an (x, y, z, w) quaternion, the order of Foxglove's and ROS 2's messages."""
    x, y, z, w = quat_xyzw(quaternion_from_yaw(yaw))
    return (x, y, z, w)


def _frame(parent: str, child: str, p: Placement) -> Frame:
    t = np.asarray(p.translation, dtype=float)
    q = np.asarray(p.quat_xyzw, dtype=float)
    return Frame(parent, child, (float(t[0]), float(t[1]), float(t[2])), (float(q[0]), float(q[1]), float(q[2]), float(q[3])))


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

    def robot(self, rid: str, hint: dict) -> RobotDrawing:
        info = self.robots.get(rid)
        # a guess from a pose alone (no type: "mobile" by hint) gives way to joint names that name the type
        if info is None or (not info.kind and hint) or (not info.type and hint.get("joint_names")):
            info = self.robots[rid] = self.catalog.drawing(rid, hint)
        return info

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
                return [_frame(WORLD, f"object/{oid}", p)]
            info = self.robot(oid, {"mobile": True})
            if info.kind == "arm":  # the flange: its own frame under the base, never the base itself
                if info.base is None:
                    return [_frame(WORLD, f"{oid}/flange", p)]
                return [_frame(oid, f"{oid}/flange", _relative(info.base, p))]
            out = [_frame(WORLD, oid, p)]
            if info.kind == "mobile":
                out.append(Frame(oid, f"{oid}/lidar", tuple(float(v) for v in info.lidar_offset), (0.0, 0.0, 0.0, 1.0)))  # type: ignore[arg-type]
                if info.sonar is not None:
                    cx, cy, h, _r = info.sonar
                    out.append(Frame(oid, f"{oid}/sonar", (cx, cy, h), (0.0, 0.0, 0.0, 1.0)))
            return out
        if isinstance(msg, JointState) and leaf == "joints" and what == "robot":
            info = self.robot(oid, {"joint_names": msg.names})
            if info.kind != "arm" or info.arm is None or len(msg.names) != len(info.arm.joint_names):
                return []
            placements = info.arm.fk(np.asarray(msg.q, dtype=float))
            out = []
            if info.base is not None:
                out.append(_frame(WORLD, oid, info.base))
            for name, pl in zip(info.arm.joint_names, placements[1:]):
                out.append(_frame(oid, f"{oid}/{name}", pl))
            return out
        return []

    def shapes(self, rid: str) -> list[tuple[str, Shape, Placement]]:
        """(frame, shape, placement in that frame) of a known robot's visual parts."""
        info = self.robots.get(rid)
        if info is None:
            return []
        if info.kind == "arm" and info.arm is not None:
            frames = [rid, *(f"{rid}/{n}" for n in info.arm.joint_names)]
            out = []
            for shape, joint, local in info.arm.shapes:
                pl = Placement(np.array(local.translation, dtype=float), _xyzw_from_matrix(np.array(local.rotation)))
                out.append((frames[joint] if joint < len(frames) else rid, shape, pl))
            return out
        if info.kind == "mobile":
            body = Shape(f"{rid}_body", "cylinder", (info.radius, info.height), color=(*info.color, 255))
            return [(rid, body, Placement(np.array([0.0, 0.0, info.height / 2.0]), np.array([0.0, 0.0, 0.0, 1.0])))]
        return []


def _relative(base: Placement, p: Placement) -> Placement:
    """``p`` (a world placement) expressed in ``base``'s frame: base^-1 * p."""
    rb = _matrix_from_xyzw(np.asarray(base.quat_xyzw, dtype=float))
    rp = _matrix_from_xyzw(np.asarray(p.quat_xyzw, dtype=float))
    t = rb.T @ (np.asarray(p.translation, dtype=float) - np.asarray(base.translation, dtype=float))
    q = _xyzw_from_matrix(rb.T @ rp)
    return Placement(t, q / np.linalg.norm(q))


def _matrix_from_xyzw(q: np.ndarray) -> np.ndarray:
    x, y, z, w = (float(v) for v in q / np.linalg.norm(q))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


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
