"""The sim's plug-in for the 2-link planar arm: what a third party writes to add a robot type.

Only the public plug-in surface is used (:mod:`sim_peer.robot`, :mod:`sim_peer.controllers`' errors,
:mod:`fabric.interfaces`); the sim peer is not touched. Its own controller, on purpose: each joint moves toward
its target at its own speed limit (not the built-in arm's synchronised straight line in joint space).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import mujoco
import numpy as np

from fabric.interfaces import JointState, Pose, RobotState
from sim_peer.controllers import Clamp, CommandRejected
from sim_peer.robot import Build, CommandHandler, Mount, Physics, SimRobot, Stream

MOVING = 1e-3  # rad/s


class Planar2Arm(SimRobot):
    kind = "arm"

    def __init__(self, mount: Mount) -> None:
        super().__init__(mount)
        d, m, p = mount.desc, mount.model, mount.prefix
        self.lower, self.upper = np.array(d.lower), np.array(d.upper)
        self.vmax = np.array(d.max_speed)
        self.q = np.zeros(2)
        self.dq = np.zeros(2)
        self.target = np.zeros(2)
        self.qadr = np.array([m.joint(p + j).qposadr[0] for j in d.joint_names])
        self.vadr = np.array([m.joint(p + j).dofadr[0] for j in d.joint_names])
        self.tip = m.site(p + d.flange_site).id

    # hooks ----------------------------------------------------------------------
    def commands(self) -> Mapping[str, CommandHandler]:
        return {"joints": self._joints, "stop": self._stop, "reset": self._reset}

    def initialize(self, physics: Physics) -> None:
        self.q[:] = self.dq[:] = self.target[:] = 0.0

    def before_step(self, physics: Physics) -> None:
        step = np.clip(self.target - self.q, -self.vmax * physics.dt, self.vmax * physics.dt)
        self.dq = step / physics.dt
        self.q = self.q + step

    def after_step(self, physics: Physics) -> None:
        physics.data.qpos[self.qadr] = self.q
        physics.data.qvel[self.vadr] = self.dq

    def streams(self) -> tuple[Stream, ...]:
        return (
            Stream("joints", "joints", self._joint_sample),
            Stream("pose", "joints", self._tip_sample, positions=True),
        )

    # commands -------------------------------------------------------------------
    def _joints(self, body: Any) -> Clamp | None:
        q = np.asarray(body.q, dtype=np.float64)
        if q.shape != (2,):
            raise CommandRejected("wrong_joint_count", f"a planar2 arm has 2 joints, got {q.shape[0]} values")
        applied = np.clip(q, self.lower, self.upper)
        self.target = applied
        bad = np.flatnonzero(applied != q)
        if bad.size == 0:
            return None
        names = self.desc.joint_names
        return Clamp(
            tuple(names[i] for i in bad), tuple(float(q[i]) for i in bad), tuple(float(applied[i]) for i in bad)
        )

    def _stop(self, body: Any) -> None:
        self.target = self.q.copy()

    def _reset(self, body: Any) -> None:
        self.target = np.zeros(2)

    # streams --------------------------------------------------------------------
    def _joint_sample(self, physics: Physics) -> Build:
        q, dq = self.q.copy(), self.dq.copy()
        return lambda header: JointState(self.desc.joint_names, q, dq, header)

    def _tip_sample(self, physics: Physics) -> Build:
        pos = physics.data.site_xpos[self.tip].copy()
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, physics.data.site_xmat[self.tip])
        return lambda header: Pose(pos, quat, frame="world", header=header)

    # state ----------------------------------------------------------------------
    @property
    def moving(self) -> bool:
        return bool(np.any(np.abs(self.dq) > MOVING))

    @property
    def kinematic_dofs(self) -> int:
        return 2

    def snapshot(self) -> RobotState:
        return RobotState(self.id, "arm", self.q, self.dq, self.target)

    def restore(self, state: RobotState) -> None:
        if state.q.shape != (2,):
            raise ValueError(f"robot {state.id}: a planar2 arm has 2 joints, the state {state.q.shape[0]}")
        self.q, self.dq, self.target = np.array(state.q), np.array(state.dq), np.array(state.target)

    def state(self, physics: Physics) -> dict[str, Any]:
        return {
            "type": self.desc.name,
            "kind": self.kind,
            "q": self.q.tolist(),
            "target": self.target.tolist(),
            "moving": self.moving,
        }
