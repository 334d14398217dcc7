"""A URDF's moving joints as transforms, as robot_state_publisher computes them: parent link -> child link.

A mobile base's URDF has links that move with its joint states (the Reeman's wheels, ``wheel_left_link`` turned by
``wheel_left``), which RViz's RobotModel needs as frames to place them; Pinocchio, which places an arm's links
(:class:`user_peer.arm_geometry.ArmGeometry`), takes a continuous joint as two coordinates (cos, sin), not the one
angle a JointState carries. Here each joint is what the URDF says and no more: the joint's origin (xyz, rpy),
then a turn about its axis by the angle (revolute, continuous) or a slide along it (prismatic), the same product
robot_state_publisher's KDL segments give. Pure: parses text once, then arithmetic per message.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

__all__ = ["MovingJoint", "moving_joints", "joint_transform"]

_MOVING = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True, slots=True)
class MovingJoint:
    """One URDF joint that moves: the links it joins, its origin (xyz, quaternion x, y, z, w) and unit axis."""

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    axis: tuple[float, float, float]


def _floats(text: str | None, default: tuple[float, float, float]) -> tuple[float, float, float]:
    if not text:
        return default
    x, y, z = (float(v) for v in text.split())
    return (x, y, z)


def _rpy_quat(r: float, p: float, y: float) -> tuple[float, float, float, float]:
    """URDF's fixed-axis roll, pitch, yaw as a quaternion (x, y, z, w)."""
    cr, sr, cp, sp, cy, sy = (
        math.cos(r / 2),
        math.sin(r / 2),
        math.cos(p / 2),
        math.sin(p / 2),
        math.cos(y / 2),
        math.sin(y / 2),
    )
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def _mul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _rotate(q: tuple[float, ...], v: tuple[float, ...]) -> tuple[float, float, float]:
    x, y, z, _w = _mul(_mul(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)


def moving_joints(urdf: str) -> dict[str, MovingJoint]:
    """The moving joints of URDF text ``urdf`` by name (fixed, floating and planar joints are left out)."""
    out = {}
    for j in ET.fromstring(urdf).iter("joint"):
        kind = j.get("type", "")
        parent, child = j.find("parent"), j.find("child")
        if kind not in _MOVING or parent is None or child is None:
            continue
        origin, axis = j.find("origin"), j.find("axis")
        xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
        rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
        a = np.asarray(_floats(axis.get("xyz") if axis is not None else None, (1.0, 0.0, 0.0)), dtype=float)
        a = a / (np.linalg.norm(a) or 1.0)
        out[j.get("name", "")] = MovingJoint(
            j.get("name", ""),
            kind,
            parent.get("link", ""),
            child.get("link", ""),
            xyz,
            _rpy_quat(*rpy),
            (float(a[0]), float(a[1]), float(a[2])),
        )
    return out


def joint_transform(j: MovingJoint, q: float) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """The child link in the parent link's frame at position ``q``: (translation, quaternion x, y, z, w)."""
    if j.type == "prismatic":
        moved = _rotate(j.quat, tuple(v * q for v in j.axis))
        return (j.xyz[0] + moved[0], j.xyz[1] + moved[1], j.xyz[2] + moved[2]), j.quat
    s = math.sin(q / 2)
    turn = (j.axis[0] * s, j.axis[1] * s, j.axis[2] * s, math.cos(q / 2))
    return j.xyz, _mul(j.quat, turn)
