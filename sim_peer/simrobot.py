"""One simulated robot in a world: its description, its controller, its MuJoCo addresses and sensors.

:class:`ArmRobot` and :class:`MobileRobot` share one command surface
(``joints``, ``twist``, ``path``, ``stop``, ``reset``) so the peer can dispatch
without caring which is which; a command a robot kind cannot take raises
:class:`CommandRejected` with reason ``unsupported``.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from robots import RobotDescription
from sim_peer.controllers import ArmController, BaseController, Clamp, CommandRejected
from sim_peer.follower import PurePursuit
from sim_peer.sensors import Lidar, Ultrasonic


class SimRobot:
    """Common surface; subclasses fill in ``apply`` (controller -> qpos) and the commands they support."""

    kind = ""

    def __init__(self, robot_id: str, desc: RobotDescription, model: mujoco.MjModel, prefix: str) -> None:
        self.id = robot_id
        self.desc = desc
        self.model = model
        self.prefix = prefix
        self.body_id = model.body(prefix + desc.root_body).id

    # commands --------------------------------------------------------------
    def joints(self, q, speed_scale: float = 1.0) -> Clamp | None:
        raise CommandRejected("unsupported", f"robot {self.id} ({self.desc.name}) does not take joint targets")

    def twist(self, v: float, omega: float) -> Clamp | None:
        raise CommandRejected("unsupported", f"robot {self.id} ({self.desc.name}) does not take twists")

    def path(self, x, y, theta) -> None:
        raise CommandRejected("unsupported", f"robot {self.id} ({self.desc.name}) does not follow paths")

    def stop(self) -> None:
        raise NotImplementedError

    def reset(self) -> None:
        raise NotImplementedError

    # stepping ---------------------------------------------------------------
    def step(self, dt: float) -> None:
        raise NotImplementedError

    def apply(self, data: mujoco.MjData) -> None:
        """Write the controller's state into ``data.qpos``/``qvel``."""
        raise NotImplementedError

    @property
    def moving(self) -> bool:
        raise NotImplementedError

    def joint_state(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        raise NotImplementedError

    def state(self, data: mujoco.MjData) -> dict[str, Any]:
        raise NotImplementedError


class ArmRobot(SimRobot):
    kind = "arm"

    def __init__(self, robot_id: str, desc: RobotDescription, model: mujoco.MjModel, prefix: str) -> None:
        super().__init__(robot_id, desc, model, prefix)
        self.ctrl = ArmController(desc.joint_names, desc.lower, desc.upper, desc.max_speed)
        self.qadr = np.array([model.joint(prefix + j).qposadr[0] for j in desc.joint_names])
        self.vadr = np.array([model.joint(prefix + j).dofadr[0] for j in desc.joint_names])
        self.flange_id = model.site(prefix + desc.flange_site).id if desc.flange_site else -1
        self._dynamic = True  # the world clears this when mj_step never runs (then only the controller writes qpos)

    def joints(self, q, speed_scale: float = 1.0) -> Clamp | None:
        return self.ctrl.set_target(q, speed_scale)

    def stop(self) -> None:
        self.ctrl.stop()

    def reset(self) -> None:
        self.ctrl.reset()

    def step(self, dt: float) -> None:
        self.ctrl.step(dt)

    def apply(self, data: mujoco.MjData) -> None:
        if self.ctrl._idle and not self._dynamic:
            return  # nothing moved and nothing else writes these joints
        data.qpos[self.qadr] = self.ctrl.q
        data.qvel[self.vadr] = self.ctrl.dq

    @property
    def moving(self) -> bool:
        return self.ctrl.moving

    def joint_state(self):
        return self.desc.joint_names, self.ctrl.q.copy(), self.ctrl.dq.copy()

    def flange(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Flange position (m) and quaternion (w, x, y, z) in the world frame."""
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, data.site_xmat[self.flange_id])
        return data.site_xpos[self.flange_id].copy(), quat

    def flange_velocity(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Linear and angular flange velocity (world frame) from the site Jacobian and the joint speeds."""
        jacp = np.zeros((3, self.model.nv))
        jacr = np.zeros((3, self.model.nv))
        mujoco.mj_jacSite(self.model, data, jacp, jacr, self.flange_id)
        return jacp[:, self.vadr] @ self.ctrl.dq, jacr[:, self.vadr] @ self.ctrl.dq

    def state(self, data: mujoco.MjData) -> dict[str, Any]:
        pos, quat = self.flange(data)
        return {
            "type": self.desc.name,
            "kind": self.kind,
            "q": [float(v) for v in self.ctrl.q],
            "target": [float(v) for v in self.ctrl.target],
            "moving": self.moving,
            "flange": [float(v) for v in pos],
        }


class MobileRobot(SimRobot):
    kind = "mobile"

    def __init__(
        self, robot_id: str, desc: RobotDescription, model: mujoco.MjModel, prefix: str, pose, rng=None, twist_timeout: float | None = None
    ) -> None:
        super().__init__(robot_id, desc, model, prefix)
        assert desc.base is not None
        self.ctrl = BaseController(desc.base, pose, twist_timeout=twist_timeout)
        self.qadr = np.array([model.joint(prefix + j).qposadr[0] for j in desc.base_joints])
        self.vadr = np.array([model.joint(prefix + j).dofadr[0] for j in desc.base_joints])
        self._qadr3 = tuple(int(a) for a in self.qadr)
        self._vadr3 = tuple(int(a) for a in self.vadr)
        self.lidar = (
            Lidar(model, desc.lidar, model.site(prefix + desc.lidar.site).id, self.body_id, rng) if desc.lidar else None
        )
        self.sonar = Ultrasonic(model, desc.ultrasonic, self.body_id, rng) if desc.ultrasonic else None

    def twist(self, v: float, omega: float) -> Clamp | None:
        return self.ctrl.twist(v, omega)

    def path(self, x, y, theta) -> None:
        b = self.desc.base
        assert b is not None
        self.ctrl.follow(PurePursuit(x, y, theta, max_speed=b.max_speed, max_omega=b.max_omega, max_accel=b.max_accel))

    def stop(self) -> None:
        self.ctrl.stop()

    def reset(self) -> None:
        self.ctrl.reset()

    def step(self, dt: float) -> None:
        self.ctrl.step(dt)

    def apply(self, data: mujoco.MjData) -> None:
        c = self.ctrl
        q, v = data.qpos, data.qvel
        qx, qy, qyaw = self._qadr3
        vx, vy, vyaw = self._vadr3
        q[qx], q[qy], q[qyaw] = c.x, c.y, c.yaw  # scalar writes: several times cheaper than fancy indexing
        v[vx], v[vy], v[vyaw] = c.v * math.cos(c.yaw), c.v * math.sin(c.yaw), c.omega

    @property
    def moving(self) -> bool:
        return self.ctrl.moving

    @property
    def following(self) -> bool:
        return self.ctrl.follower is not None

    def joint_state(self):
        return self.desc.joint_names, self.ctrl.wheels.copy(), self.ctrl.wheel_speeds.copy()

    def pose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Position, quaternion (w, x, y, z), linear and angular velocity of the axle midpoint, world frame."""
        c = self.ctrl
        z = 0.0
        pos = np.array([c.x, c.y, z])
        quat = np.array([math.cos(c.yaw / 2), 0.0, 0.0, math.sin(c.yaw / 2)])
        lin = np.array([c.v * math.cos(c.yaw), c.v * math.sin(c.yaw), 0.0])
        ang = np.array([0.0, 0.0, c.omega])
        return pos, quat, lin, ang

    def state(self, data: mujoco.MjData) -> dict[str, Any]:
        c = self.ctrl
        return {
            "type": self.desc.name,
            "kind": self.kind,
            "pose": [c.x, c.y, c.yaw],
            "twist": [c.v, c.omega],
            "moving": self.moving,
            "following": self.following,
        }
