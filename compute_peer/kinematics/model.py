"""One arm's kinematics: Pinocchio model from the URDF the sim uses (no second copy of the geometry)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

import robots


class NoIKSolution(ValueError):
    """No joint solution puts the flange at the target inside the joint limits; the message says why.

    The solvers' refusal, inside the compute peer: the service sends its text back as a
    :class:`fabric.interfaces.Refused` reply, which the user API raises as ``user_peer.Unreachable``
    (the one class of that name: a target a user asked for cannot be reached)."""


def arm_model(desc: robots.RobotDescription) -> pin.Model:
    """The Pinocchio model of the description's arm: its URDF with every joint the description does not list
    (a gripper's fingers, another branch) held at zero, so the model's coordinates are the description's joints,
    in its order. ``ValueError`` when the URDF lacks one of them or orders them otherwise. (A continuous joint
    stays two coordinates here: ``robots add`` writes it revolute.)"""
    full = pin.buildModelFromUrdf(str(desc.urdf_path))
    names = list(full.names)[1:]
    missing = [j for j in desc.joint_names if j not in names]
    if missing:
        raise ValueError(f"robot {desc.name!r}: joints {', '.join(missing)} are not in {desc.urdf_path}")
    lock = [full.getJointId(n) for n in names if n not in desc.joint_names]
    model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
    if tuple(model.names)[1:] != desc.joint_names:
        raise ValueError(
            f"robot {desc.name!r}: the URDF's joints {list(model.names)[1:]} are not the description's "
            f"{list(desc.joint_names)} in that order"
        )
    return model


class ArmModel:
    """FK, geometric Jacobian (paper Eq. 3-6), Eq. 7 speeds and DLS IK for one robot type."""

    def __init__(self, robot_type: str) -> None:
        desc = robots.load(robot_type)
        if desc.urdf_path is None:
            raise ValueError(f"robot {robot_type!r} has no URDF")
        self.description = desc
        self.model = arm_model(desc)
        self.data = self.model.createData()
        frame = desc.flange_frame or self.model.frames[-1].name
        self.frame_id = self.model.getFrameId(frame)
        self.lower = np.asarray(desc.lower, float)
        # each joint's axis in its own frame, read once from the model (constant for 1-dof joints): the angular
        # part of its column for a revolute joint, the linear part for a prismatic one
        pin.computeJointJacobians(self.model, self.data, pin.neutral(self.model))
        cols = [
            pin.getJointJacobian(self.model, self.data, i, pin.LOCAL)[:, i - 1].copy()
            for i in range(1, self.model.njoints)
        ]
        self._prismatic = [bool(np.linalg.norm(c[3:]) < 0.5) for c in cols]
        self._axes = [c[:3] if p else c[3:] for c, p in zip(cols, self._prismatic)]
        self.upper = np.asarray(desc.upper, float)

    def fk(self, q: np.ndarray) -> pin.SE3:
        """Flange pose in the base frame."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, float))
        return self.data.oMf[self.frame_id].copy()

    def joint_frames(self, q: np.ndarray) -> list[pin.SE3]:
        """World placements of the joints (their z axes are z_{i-1} of Eq. 4-5)."""
        pin.forwardKinematics(self.model, self.data, np.asarray(q, float))
        return [self.data.oMi[i].copy() for i in range(1, self.model.njoints)]

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """6xN geometric Jacobian, written out as the paper's Eq. 4-6 for N joints: [z x (o_n - o_i); z] for a
        revolute joint, [z; 0] for a prismatic one."""
        o_n = self.fk(q).translation
        cols = []
        for i, m in enumerate(self.joint_frames(q), start=1):
            # z_{i-1}: the joint axis in the world (URDF axes need not be local z)
            z = m.rotation @ self._axes[i - 1]
            if self._prismatic[i - 1]:
                cols.append(np.concatenate([z, np.zeros(3)]))
            else:
                cols.append(np.concatenate([np.cross(z, o_n - m.translation), z]))
        return np.stack(cols, axis=1)

    def joint_speed_magnitudes(
        self, q: np.ndarray, dq: np.ndarray, *, jacobian: np.ndarray | None = None
    ) -> np.ndarray:
        """Eq. 7: per joint, the norm of its column's linear+angular contribution times its rate.

        ``jacobian`` is J(q) when the caller has it already, in any frame: a rotation of both halves of a
        column keeps its norm, so the speeds are the same in the base and the world frame.
        """
        j = self.jacobian(q) if jacobian is None else jacobian
        return np.linalg.norm(j, axis=0) * np.abs(np.asarray(dq, float))

    def ik_position(
        self, target: np.ndarray, q0: np.ndarray, *, tol: float = 1e-9, iters: int = 200, damping: float = 1e-4
    ) -> np.ndarray:
        """Damped least squares on the position, clamped to limits; raises NoIKSolution on failure."""
        target = np.asarray(target, float)
        if not np.all(np.isfinite(target)):
            raise NoIKSolution("target is not finite")
        q = np.clip(np.asarray(q0, float), self.lower, self.upper)
        for _ in range(iters):
            err = target - self.fk(q).translation
            if float(err @ err) < tol * tol:
                return q
            jv = self.jacobian(q)[:3]
            dq = jv.T @ np.linalg.solve(jv @ jv.T + damping * np.eye(3), err)
            q = np.clip(q + dq, self.lower, self.upper)
        raise NoIKSolution(
            f"no joint solution within limits for {target.tolist()} (residual {np.linalg.norm(err):.3g} m)"
        )
