"""An arm of another sim, as the link geoms this sim's sensors meet: its joint stream turned into geom poses.

A mirrored arm is one mirror slot per link geom (:mod:`sim_peer.physics.mirrors`). Where each goes is forward
kinematics of the arm's own MJCF, compiled alone once per robot type (a few microseconds per joint
message), at the joint angles its sim publishes, carried to where the world spawned it (its ``RobotInfo``
pose, through the robot class's attach frame: the same frame the arm's own sim attaches it at). Only the
geoms sensors see (the robots' geom group) are mirrored, and only primitives: a mesh geom would need its
mesh in this sim's model, which is compiled before any other sim is known.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

import mujoco
import numpy as np

import robots as robots_pkg
from fabric.interfaces import RobotInfo
from robots import RobotDescription
from sim_peer.physics.mirrors import MIRROR_GROUP, Shape, PRIMITIVES
from sim_peer.physics.registry import robot_class

__all__ = ["ArmShape", "arm_shape"]


class ArmShape:
    """One arm of another sim: its link shapes, and their world poses at given joint angles.

    Not thread-safe (one MjData); the mirror feed calls it under its lock."""

    def __init__(self, desc: RobotDescription, info: RobotInfo) -> None:
        self.robot = info.id
        spec = mujoco.MjSpec.from_file(str(desc.mjcf_path))
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self._geoms = [
            g
            for g in range(self.model.ngeom)
            if self.model.geom_group[g] == MIRROR_GROUP and int(self.model.geom_type[g]) in PRIMITIVES
        ]
        if not self._geoms:
            raise ValueError(f"robot type {desc.name}: no primitive geom in the robots' group {MIRROR_GROUP} to mirror")
        self.shapes: tuple[Shape, ...] = tuple(
            (int(self.model.geom_type[g]), tuple(float(x) for x in self.model.geom_size[g])) for g in self._geoms
        )
        # the stream's joints (by the world description's names) -> this model's qpos addresses
        qadr = {}
        for j in range(self.model.njnt):
            qadr[mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_JOINT, j)] = int(self.model.jnt_qposadr[j])
        missing = [n for n in info.joint_names if n not in qadr]
        if missing:
            raise ValueError(f"{info.id}: joints {missing} are not in {desc.mjcf_path.name}")
        self._qadr = np.array([qadr[n] for n in info.joint_names], dtype=np.int64)
        x, y, z, yaw = (float(v) for v in info.pose)
        pos, quat = robot_class(desc).frame((x, y, z, yaw))
        self._origin = np.asarray(pos, dtype=np.float64)
        self._turn = np.zeros(9)
        mujoco.mju_quat2Mat(self._turn, np.asarray(quat, dtype=np.float64))
        self._turn = self._turn.reshape(3, 3)
        self._quat = np.asarray(quat, dtype=np.float64)
        self._q = np.zeros(4)

    @property
    def joints(self) -> int:
        return int(self._qadr.shape[0])

    @property
    def geoms(self) -> tuple[int, ...]:
        """The ids, in its model, of the geoms mirrored, in the order of ``shapes`` and of :meth:`poses`."""
        return tuple(self._geoms)

    def poses(self, q: Sequence[float]) -> list[tuple[np.ndarray, np.ndarray]] | None:
        """Each mirrored geom's world centre and quaternion with the arm at ``q``; None for a wrong length or a
        non-finite angle (a malformed message moves nothing)."""
        q = np.asarray(q, dtype=np.float64)
        if q.shape != self._qadr.shape or not np.isfinite(q).all():
            return None
        self.data.qpos[self._qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        out = []
        for g in self._geoms:
            centre = self._origin + self._turn @ self.data.geom_xpos[g]
            local = np.zeros(4)
            mujoco.mju_mat2Quat(local, self.data.geom_xmat[g])
            mujoco.mju_mulQuat(self._q, self._quat, local)
            out.append((centre, self._q.copy()))
        return out


_cache: dict[str, RobotDescription] = {}
_lock = threading.Lock()


def arm_shape(info: RobotInfo) -> ArmShape:
    """The mirror shape of the arm ``info`` describes (its type's description loaded once per process);
    ``ValueError`` when its type is unknown here or its model has nothing to mirror."""
    with _lock:
        desc = _cache.get(info.type)
        if desc is None:
            try:
                desc = robots_pkg.installed(
                    info.type
                )  # a name another sim sent: never a path (nothing it names runs here)
            except robots_pkg.DescriptionError as exc:
                raise ValueError(f"{info.id}: robot type {info.type!r} is not installed here: {exc}") from None
            _cache[info.type] = desc
    return ArmShape(desc, info)
