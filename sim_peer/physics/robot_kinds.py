"""The two built-in robot types: :class:`ArmRobot` (joint position control) and :class:`MobileRobot`
(a differential-drive base with its sensors), as plug-ins with the hooks of :mod:`sim_peer.robot`.

Each keeps its command methods (``joints``, ``twist``, ``path``, ``stop``, ``reset``) for tests and tools;
``commands()`` lists the ones the peer may route to it, so a command a type does not list is refused with
reason ``unsupported`` without the peer knowing which type it is.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import mujoco
import numpy as np

from fabric.interfaces import BaseInfo, EventKind, JointState, Pose, RobotInfo, RobotState
from sim_peer.bumper import Bumper
from sim_peer.controllers import ArmController, BaseController, Clamp, CommandRejected
from sim_peer.physics.pure_pursuit import PurePursuit
from sim_peer.physics.way_guard import WayGuard
from sim_peer.robot import Build, CommandHandler, Mount, Note, Physics, SimRobot, Stream, check_hooks
from sim_peer.sensors import Lidar, Sensor, Ultrasonic


def _joint_addresses(model: mujoco.MjModel, prefix: str, names) -> tuple[np.ndarray, np.ndarray]:
    qadr = np.array([model.joint(prefix + j).qposadr[0] for j in names], dtype=np.int64)
    vadr = np.array([model.joint(prefix + j).dofadr[0] for j in names], dtype=np.int64)
    return qadr, vadr


def _joint_stream(robot: Any) -> Stream:
    def read(physics: Physics) -> Build:
        names, q, dq = robot.joint_state()
        return lambda header: JointState(names, q, dq, header)

    return Stream("joints", "joints", read)


def _pose_stream(robot: Any) -> Stream:
    """A base's pose (axle midpoint) with its velocities, from its controller."""

    def read(physics: Physics) -> Build:
        pos, quat, lin, ang = robot.ctrl.pose()
        return lambda header: Pose(pos, quat, lin, ang, "world", header)

    return Stream("pose", "pose", read)


_NEWS = {
    EventKind.PATH_DONE: "path followed to its end",
    EventKind.TWIST_TIMEOUT: "no fresh twist within the timeout: stopping",
}
"""What a base's controller tells (``BaseController.on_news``), as the event a robot notes."""


def _world_path(body: Any) -> tuple[Any, Any, Any]:
    """The waypoints of a ``cmd/path`` body; a base follows paths in the world frame only."""
    if body.frame not in ("world", ""):
        raise CommandRejected("bad_frame", f"paths must be in the world frame, got {body.frame!r}")
    return body.x, body.y, body.theta


class _Driven(SimRobot):
    """A robot whose controller ``ctrl`` moves it and writes the joints at ``vadr`` itself (both types)."""

    ctrl: ArmController | BaseController
    vadr: np.ndarray

    @property
    def moving(self) -> bool:
        return self.ctrl.moving

    @property
    def kinematic_dofs(self) -> int:
        return len(self.vadr)

    # commands: what a type does not take is refused, with its reason ----------
    def joints(self, q, speed_scale: float = 1.0) -> Clamp | None:
        raise self.unsupported("take joint targets")

    def twist(self, v: float, omega: float) -> Clamp | None:
        raise self.unsupported("take twists")

    def path(self, x, y, theta) -> None:
        raise self.unsupported("follow paths")

    def stop(self) -> None:
        self.ctrl.stop()

    def reset(self) -> None:
        self.ctrl.reset()


@check_hooks
class ArmRobot(_Driven):
    """An arm driven joint by joint toward a target; publishes its joints and, with them, its flange pose."""

    kind = "arm"

    def __init__(self, mount: Mount) -> None:
        super().__init__(mount)
        desc, model, prefix = mount.desc, mount.model, mount.prefix
        self.ctrl = ArmController(desc.joint_names, desc.lower, desc.upper, desc.max_speed)
        self.qadr, self.vadr = _joint_addresses(model, prefix, desc.joint_names)
        self.flange_id = model.site(prefix + desc.flange_site).id if desc.flange_site else -1

    # commands ---------------------------------------------------------------
    def commands(self) -> Mapping[str, CommandHandler]:
        return {
            "joints": lambda body: self.joints(body.q, body.speed_scale),
            "trajectory": lambda body: self.ctrl.set_trajectory(body.times, body.positions),
            "stop": lambda body: self.stop(),
            "reset": lambda body: self.reset(),
        }

    def joints(self, q, speed_scale: float = 1.0) -> Clamp | None:
        return self.ctrl.set_target(q, speed_scale)

    @property
    def underway(self) -> bool:
        """Moving, or with a target it has not reached: a target taken just before a hold, with no step since, has no
        speed yet (the three-pause test's last moves were lost so: their riders were never told to send them again)."""
        return self.ctrl.moving or bool(np.any(self.ctrl.goal != self.ctrl.q))

    # hooks ------------------------------------------------------------------
    def initialize(self, physics: Physics) -> None:
        self.ctrl.teleport(np.zeros(self.ctrl.dof))

    def before_step(self, physics: Physics) -> None:
        self.ctrl.step(physics.dt)

    def after_step(self, physics: Physics) -> None:
        if self.ctrl.idle and not physics.dynamic:
            return  # nothing moved and nothing else writes these joints
        physics.data.qpos[self.qadr] = self.ctrl.q
        physics.data.qvel[self.vadr] = self.ctrl.dq

    def streams(self) -> tuple[Stream, ...]:
        out = [_joint_stream(self)]
        if self.flange_id >= 0:
            out.append(Stream("pose", "joints", self._flange_sample, positions=True))
        return tuple(out)

    def _flange_sample(self, physics: Physics) -> Build:
        pos, quat = self.flange(physics.data)
        lin, ang = self.flange_velocity(physics.data)
        return lambda header: Pose(pos, quat, lin, ang, "world", header)

    # state ------------------------------------------------------------------
    def snapshot(self) -> RobotState:
        c = self.ctrl
        return RobotState(self.id, "arm", c.q, c.dq, c.goal, extra={"scale": c.scale, "idle": bool(c.idle)})

    def restore(self, state: RobotState) -> None:
        c = self.ctrl
        if state.kind != self.kind or state.q.shape != c.q.shape:
            raise ValueError(
                f"robot {state.id}: state of a {state.kind} with {state.q.shape[0]} joints for an arm with {c.dof}"
            )
        c.restore(state.q, state.dq, state.target, float(state.extra.get("scale", 1.0)))

    def overlay(self, stream: str, message: Any) -> None:
        if stream == "joints" and message.q.shape == self.ctrl.q.shape:
            self.ctrl.restore(message.q, message.dq)

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

    def state(self, physics: Physics) -> dict[str, Any]:
        pos, _ = self.flange(physics.data)
        return {
            "type": self.desc.name,
            "kind": self.kind,
            "q": [float(v) for v in self.ctrl.q],
            "target": [float(v) for v in self.ctrl.target],
            "moving": self.moving,
            "flange": [float(v) for v in pos],
        }


@check_hooks
class MobileRobot(_Driven):
    """A differential-drive base (twists, paths) with a LIDAR, an ultrasonic ring and a bumper as its sensors."""

    kind = "mobile"

    def __init__(self, mount: Mount) -> None:
        super().__init__(mount)
        desc, model, prefix = mount.desc, mount.model, mount.prefix
        assert desc.base is not None
        x, y, _, yaw = mount.pose
        self.ctrl = BaseController(
            desc.base,
            (x, y, yaw),
            twist_timeout=mount.twist_timeout,
            on_news=lambda news: self.note(Note(news, _NEWS[news])),
        )
        self.qadr, self.vadr = _joint_addresses(model, prefix, desc.base_joints)
        self._qadr3 = tuple(int(a) for a in self.qadr)
        self._vadr3 = tuple(int(a) for a in self.vadr)
        self.lidar = (
            Lidar(model, desc.lidar, model.site(prefix + desc.lidar.site).id, self.body_id, mount.rng)
            if desc.lidar
            else None
        )
        self.sonar = Ultrasonic(model, desc.ultrasonic, self.body_id, mount.rng) if desc.ultrasonic else None
        self.bumper = Bumper(self, float(model.opt.timestep)) if mount.bumper else None
        self.guard = (
            WayGuard(self, float(model.opt.timestep), traffic=mount.traffic) if self.lidar is not None else None
        )  # stops before robots in its way
        self.sensors: tuple[Sensor, ...] = tuple(
            s for s in (self.lidar, self.sonar, self.bumper, self.guard) if s is not None
        )
        checked = [s for s in self.sensors if type(s).after_step is not Sensor.after_step]
        self._checks = tuple((s.after_step, s.every) for s in checked)
        self._check_every = math.gcd(*(s.every for s in checked)) if checked else 0  # steps between sensor checks

    @staticmethod
    def frame(pose: tuple[float, float, float, float]) -> tuple[list[float], list[float]]:
        """At the height of the pose only: the base joints carry x, y and yaw."""
        return [0.0, 0.0, pose[2]], [1.0, 0.0, 0.0, 0.0]

    # commands ---------------------------------------------------------------
    def commands(self) -> Mapping[str, CommandHandler]:
        return {
            "twist": lambda body: self.twist(body.v, body.omega),
            "path": lambda body: self.path(*_world_path(body)),
            "stop": lambda body: self.stop(),
            "reset": lambda body: self.reset(),
        }

    def twist(self, v: float, omega: float) -> Clamp | None:
        return self.ctrl.twist(v, omega)

    def path(self, x, y, theta) -> None:
        b = self.desc.base
        assert b is not None
        self.ctrl.follow(PurePursuit(x, y, theta, max_speed=b.max_speed, max_omega=b.max_omega, max_accel=b.max_accel))

    def halt(self) -> None:
        """Its owner let go: brake to a halt within the base's limits (a stop command stops at once)."""
        self.ctrl.brake()

    # hooks ------------------------------------------------------------------
    def describe(self) -> RobotInfo:
        b = self.desc.base
        assert b is not None
        info = replace(
            super().describe(),
            base=BaseInfo(
                radius=b.radius,
                height=b.height,
                wheel_separation=b.wheel_separation,
                wheel_radius=b.wheel_radius,
                max_speed=b.max_speed,
                max_omega=b.max_omega,
                max_accel=b.max_accel,
                max_alpha=b.max_alpha,
                reverse=int(b.reverse),
            ),
        )
        for s in self.sensors:
            info = s.describe(info)
        return info

    def initialize(self, physics: Physics) -> None:
        self.ctrl.reset()

    def before_step(self, physics: Physics) -> None:
        self.ctrl.step(physics.dt)

    def after_step(self, physics: Physics) -> None:
        c, d = self.ctrl, physics.data
        q, v = d.qpos, d.qvel
        qx, qy, qyaw = self._qadr3
        vx, vy, vyaw = self._vadr3
        q[qx], q[qy], q[qyaw] = c.x, c.y, c.yaw  # scalar writes: several times cheaper than fancy indexing
        v[vx], v[vy], v[vyaw] = c.v * math.cos(c.yaw), c.v * math.sin(c.yaw), c.omega
        every = self._check_every
        if every and not physics.steps % every and physics.stepping:
            for check, every in self._checks:
                if not physics.steps % every:
                    check(physics)

    def streams(self) -> tuple[Stream, ...]:
        own = (_joint_stream(self), _pose_stream(self))
        return own + tuple(st for s in self.sensors for st in s.streams())

    # state ------------------------------------------------------------------
    def snapshot(self) -> RobotState:
        c = self.ctrl
        extra: dict[str, Any] = {
            "wheels": [float(w) for w in c.wheels],
            "wheel_speeds": [float(w) for w in c.wheel_speeds],
            "since_twist": c.since_twist,
            "twists_expired": c.twists_expired,
            "paths_done": c.paths_done,
        }
        path = np.zeros((0, 2))
        f = c.follower
        if isinstance(f, PurePursuit):
            path = f.points
            extra.update(
                index=f.index,
                stretch=f.stretch,
                arrived=bool(f.arrived),
                done=bool(f.done),
                backwards=[bool(b) for b in f.backwards],  # the headings that said so are not sent on
            )
            if f.final_yaw is not None:
                extra["final_yaw"] = float(f.final_yaw)
        return RobotState(self.id, "mobile", [c.x, c.y, c.yaw], [c.v, c.omega], [c.v_cmd, c.omega_cmd], path, extra)

    def restore(self, state: RobotState) -> None:
        c = self.ctrl
        if state.kind != self.kind or state.q.shape != (3,):
            raise ValueError(f"robot {state.id}: state of a {state.kind} for a mobile base")
        c.x, c.y, c.yaw = (float(v) for v in state.q)
        c.v, c.omega = (float(v) for v in state.dq)
        c.v_cmd, c.omega_cmd = (float(v) for v in state.target)
        e = state.extra
        c.wheels[:] = e.get("wheels", [0.0, 0.0])
        c.wheel_speeds[:] = e.get("wheel_speeds", [0.0, 0.0])
        c.resume_twist_clock(float(e.get("since_twist", 0.0)))
        c.twists_expired = int(e.get("twists_expired", 0))
        c.paths_done = int(e.get("paths_done", 0))
        c.follower = None
        if state.path.shape[0]:
            b = self.desc.base
            assert b is not None
            f = PurePursuit(
                state.path[:, 0],
                state.path[:, 1],
                None,
                max_speed=b.max_speed,
                max_omega=b.max_omega,
                max_accel=b.max_accel,
            )
            f.final_yaw = float(e["final_yaw"]) if "final_yaw" in e else None
            backwards = [bool(b) for b in e.get("backwards", ())]
            if len(backwards) == len(f.stops):  # a state from a sim before it was carried: forwards, as then
                f.backwards = backwards
            f.index = min(int(e.get("index", 0)), f.points.shape[0] - 1)
            f.stretch = min(int(e.get("stretch", 0)), len(f.stops) - 1)
            f.arrived, f.done = bool(e.get("arrived", False)), bool(e.get("done", False))
            c.follower = f

    def overlay(self, stream: str, message: Any) -> None:
        """The base's pose from its stream: position, heading and the velocities the stream carries."""
        if stream != "pose":
            return
        c = self.ctrl
        c.x, c.y = float(message.position[0]), float(message.position[1])
        w, z = float(message.quaternion[0]), float(message.quaternion[3])
        c.yaw = 2.0 * math.atan2(z, w)
        c.v = float(message.linear[0] * math.cos(c.yaw) + message.linear[1] * math.sin(c.yaw))
        c.omega = float(message.angular[2])

    @property
    def following(self) -> bool:
        return self.ctrl.follower is not None

    def joint_state(self):
        return self.desc.joint_names, self.ctrl.wheels.copy(), self.ctrl.wheel_speeds.copy()

    def state(self, physics: Physics) -> dict[str, Any]:
        c = self.ctrl
        return {
            "type": self.desc.name,
            "kind": self.kind,
            "pose": [c.x, c.y, c.yaw],
            "twist": [c.v, c.omega],
            "moving": self.moving,
            "following": self.following,
        }


__all__ = ["ArmRobot", "MobileRobot"]
