"""One arm placed in a world: the kinematics services' pure core (no Zenoh, no clock).

The solvers (:mod:`.model`, :mod:`.ik`) work in the arm's base frame; users and
the viewer work in the world frame, where the scene put the arm's base at
(x, y, z, yaw). :class:`PlacedArm` does that conversion once, in one place, and
answers IK, FK, Jacobian and the streamed solution of Test A.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from .ik import IKSolution, solve
from .model import ArmModel

__all__ = ["PlacedArm", "StreamStep", "finite_vector"]


def finite_vector(value: Sequence[float], n: int, what: str) -> np.ndarray:
    """``value`` as a float vector of length ``n``; ``ValueError`` naming ``what`` otherwise."""
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape[0] != n:
        raise ValueError(f"{what} needs {n} values, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} is not finite: {arr.tolist()}")
    return arr


def _quat_wxyz(rot: np.ndarray) -> np.ndarray:
    x, y, z, w = pin.Quaternion(rot).coeffs()
    q = np.array([w, x, y, z])
    return q if w >= 0 else -q


def _rot_wxyz(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = (float(v) for v in np.asarray(quat, float) / np.linalg.norm(quat))
    return pin.Quaternion(w, x, y, z).toRotationMatrix()


@dataclass(frozen=True, slots=True)
class StreamStep:
    """One streamed IK result: joints for the target, or why not, and the move from the current joints."""

    ok: bool
    reason: str
    q: np.ndarray
    dq: np.ndarray
    speeds: np.ndarray
    seconds: float


class PlacedArm:
    """An :class:`ArmModel` whose base sits at ``pose`` = (x, y, z, yaw) in the world."""

    def __init__(
        self, model: ArmModel, pose: Sequence[float] = (0.0, 0.0, 0.0, 0.0), max_speed: Sequence[float] | None = None
    ) -> None:
        self.model = model
        x, y, z, yaw = (float(v) for v in finite_vector(pose, 4, "base pose"))
        c, s = math.cos(yaw), math.sin(yaw)
        self.rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        self.origin = np.array([x, y, z])
        self.nq = int(model.lower.shape[0])
        speeds = model.description.max_speed if max_speed is None else max_speed
        self.max_speed = finite_vector(speeds, self.nq, "max_speed")

    # ------------------------------------------------------------------ frames

    def to_base(
        self, position: np.ndarray, quaternion: np.ndarray | None, frame: str
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """A world (or base) target expressed in the base frame; quaternion None stays None."""
        p = finite_vector(position, 3, "position")
        rot = None if quaternion is None else _rot_wxyz(quaternion)
        if frame == "base":
            return p, None if rot is None else _quat_wxyz(rot)
        p = self.rotation.T @ (p - self.origin)
        return p, None if rot is None else _quat_wxyz(self.rotation.T @ rot)

    def _q(self, q: Sequence[float]) -> np.ndarray:
        return finite_vector(q, self.nq, "joints")

    # ------------------------------------------------------------------ services

    def ik(
        self,
        position: Sequence[float],
        quaternion: Sequence[float] | None = None,
        seed: Sequence[float] | None = None,
        *,
        frame: str = "world",
        method: str = "auto",
    ) -> IKSolution:
        """Joints for a flange target in ``frame``; :class:`~.model.NoIKSolution` with the reason when none."""
        quat = None if quaternion is None or len(quaternion) == 0 else finite_vector(quaternion, 4, "quaternion")
        if quat is not None and float(np.linalg.norm(quat)) < 1e-6:
            raise ValueError("quaternion has zero norm")
        p, qb = self.to_base(np.asarray(position, float), quat, frame)
        s = None if seed is None or len(seed) == 0 else self._q(seed)
        return solve(self.model, p, qb, s, method=method)

    def fk(self, q: Sequence[float], frame: str = "world") -> tuple[np.ndarray, np.ndarray]:
        """Flange position and quaternion (w, x, y, z) in ``frame``."""
        m = self.model.fk(self._q(q))
        if frame == "base":
            return m.translation.copy(), _quat_wxyz(m.rotation)
        return self.rotation @ m.translation + self.origin, _quat_wxyz(self.rotation @ m.rotation)

    def jacobian(
        self, q: Sequence[float], dq: Sequence[float] | None = None, frame: str = "world"
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(J, twist, Eq. 7 speeds); the last two empty without ``dq``. World frame rotates both halves of J."""
        qv = self._q(q)
        j = self.model.jacobian(qv)
        if frame == "world":
            j = np.vstack([self.rotation @ j[:3], self.rotation @ j[3:]])
        if dq is None or len(dq) == 0:
            return j, np.zeros(0), np.zeros(0)
        dqv = finite_vector(dq, self.nq, "joint rates")
        return j, j @ dqv, self.model.joint_speed_magnitudes(qv, dqv, jacobian=j)

    def move(self, q_now: np.ndarray, q_goal: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """A synchronised move at the speed limits: joint rates, their Eq. 7 speeds (at ``q_now``), duration."""
        delta = q_goal - q_now
        seconds = float(np.max(np.abs(delta) / self.max_speed)) if self.nq else 0.0
        if seconds <= 0.0:
            return np.zeros(self.nq), np.zeros(self.nq), 0.0
        dq = delta / seconds
        _, _, speeds = self.jacobian(q_now, dq, "world")
        return dq, speeds, seconds

    def stream_step(self, position: Sequence[float], q_now: np.ndarray | None) -> StreamStep:
        """Test A: position-only IK for the target sphere near the current joints, and the move to it."""
        from .model import NoIKSolution

        now = np.zeros(self.nq) if q_now is None else self._q(q_now)
        try:
            sol = self.ik(position, None, now)
        except (NoIKSolution, ValueError) as exc:
            empty = np.zeros(0)
            return StreamStep(False, str(exc), empty, empty, empty, 0.0)
        dq, speeds, seconds = self.move(now, sol.q)
        return StreamStep(True, "", sol.q, dq, speeds, seconds)
