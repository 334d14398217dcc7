"""An arm's joint frames from its URDF in numpy: where each joint sits for a JointState, without Pinocchio.

The console draws the arm's links in its top view on a student's install, which has no Pinocchio (the
``compute`` extra brings it); :class:`~user_peer.arm_geometry.ArmGeometry` is the full model (shapes,
meshes) where Pinocchio is installed. This reads only what a drawing of the chain needs: each joint's
parent, origin (xyz, rpy), axis and kind; revolute, continuous and prismatic joints take one value of
``q`` each, in the order a depth-first walk from the root meets them (Pinocchio's order, tested against it).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ["ChainJoint", "UrdfChain", "UrdfError"]

MOVING = ("revolute", "continuous", "prismatic")


class UrdfError(ValueError):
    """A URDF this module cannot read (no joints, a cycle, a bad number)."""


@dataclass(frozen=True, slots=True)
class ChainJoint:
    name: str
    kind: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: Rz(y) Ry(p) Rx(r)."""
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _axis_angle(axis: np.ndarray, a: float) -> np.ndarray:
    x, y, z = axis
    c, s, t = math.cos(a), math.sin(a), 1 - math.cos(a)
    return np.array(
        [
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ]
    )


def _floats(text: str | None, default: tuple[float, float, float], what: str) -> tuple[float, float, float]:
    if text is None:
        return default
    try:
        v = tuple(float(x) for x in text.split())
    except ValueError:
        raise UrdfError(f"{what}: {text!r} is not three numbers") from None
    if len(v) != 3:
        raise UrdfError(f"{what}: {text!r} is not three numbers")
    return v  # type: ignore[return-value]


class UrdfChain:
    """The joints of a URDF in walk order; :meth:`origins` places them for a joint vector."""

    def __init__(self, urdf_text: str) -> None:
        try:
            root = ET.fromstring(urdf_text)
        except ET.ParseError as exc:
            raise UrdfError(f"not XML: {exc}") from None
        joints = []
        for j in root.iter("joint"):
            parent, child = j.find("parent"), j.find("child")
            if parent is None or child is None:
                raise UrdfError(f"joint {j.get('name')!r} has no parent or child")
            origin = j.find("origin")
            axis = j.find("axis")
            joints.append(
                ChainJoint(
                    j.get("name", ""),
                    j.get("type", "fixed"),
                    parent.get("link", ""),
                    child.get("link", ""),
                    _floats(
                        origin.get("xyz") if origin is not None else None,
                        (0.0, 0.0, 0.0),
                        f"joint {j.get('name')} origin",
                    ),
                    _floats(
                        origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0), f"joint {j.get('name')} rpy"
                    ),
                    _floats(
                        axis.get("xyz") if axis is not None else None, (1.0, 0.0, 0.0), f"joint {j.get('name')} axis"
                    ),
                )
            )
        if not joints:
            raise UrdfError("no joints")
        by_parent: dict[str, list[ChainJoint]] = {}
        for j in joints:
            by_parent.setdefault(j.parent, []).append(j)
        roots = {j.parent for j in joints} - {j.child for j in joints}
        if len(roots) != 1:
            raise UrdfError(f"expected one root link, found {sorted(roots) or 'none (a cycle)'}")
        self.root = roots.pop()
        self.joints: list[ChainJoint] = []
        stack = list(reversed(by_parent.get(self.root, [])))
        while stack:  # depth first, children in document order
            j = stack.pop()
            self.joints.append(j)
            stack.extend(reversed(by_parent.get(j.child, [])))
        self.moving = [j.name for j in self.joints if j.kind in MOVING]
        self._parent_index = [
            next((k for k, p in enumerate(self.joints) if p.child == j.parent), -1) for j in self.joints
        ]

    @classmethod
    def from_file(cls, path: str | Path) -> "UrdfChain":
        return cls(Path(path).read_text())

    @property
    def nq(self) -> int:
        return len(self.moving)

    def origins(self, q: Sequence[float]) -> np.ndarray:
        """Every joint frame's origin in the root link's frame, in walk order (fixed joints too): (N, 3)."""
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape[0] != self.nq:
            raise ValueError(f"the chain has {self.nq} moving joints, got {q.shape[0]} values")
        rots: list[np.ndarray] = []
        pos: list[np.ndarray] = []
        k = 0
        for i, j in enumerate(self.joints):
            pi = self._parent_index[i]
            R0, p0 = (rots[pi], pos[pi]) if pi >= 0 else (np.eye(3), np.zeros(3))
            R = R0 @ _rpy(*j.rpy)
            p = p0 + R0 @ np.asarray(j.xyz)
            if j.kind in MOVING:
                axis = np.asarray(j.axis) / (np.linalg.norm(j.axis) or 1.0)
                if j.kind == "prismatic":
                    p = p + R @ axis * q[k]
                else:
                    R = R @ _axis_angle(axis, q[k])
                k += 1
            rots.append(R)
            pos.append(p)
        return np.array(pos).reshape(-1, 3)
