"""A world's whole state as a message, and putting a world back into it (issue 16).

The primary serves :class:`WorldState` on ``rf/{world}/srv/state``; a standby polls it and keeps the
last one, together with the newest joints and poses from the streams (which come ten times more
often). On take-over :func:`restore` puts every robot and object back where it was (no reset) and
every controller back on its way: an arm's joint target and speed scale, a base's commanded twist,
a path follower's points and progress. What is not captured cannot be restored: MuJoCo's own
dynamic state of free bodies and contacts in progress (the robots here are kinematic), sensor noise
streams (the standby's generator is its own) and commands that arrived after the last snapshot
(see docs/sim.md).

No zenoh here: the peer and the standby do the I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from fabric.messages import JointState, Pose
from sim_peer.follower import PurePursuit
from sim_peer.messages import ObjectInfo, RobotState, WorldState
from sim_peer.simrobot import ArmRobot, MobileRobot
from sim_peer.world import SimWorld

__all__ = ["RobotState", "WorldState", "capture", "restore", "overlay_joints", "overlay_pose", "advance"]


# ---------------------------------------------------------------------- capture


def _robot_state(rid: str, r: Any) -> RobotState:
    if isinstance(r, ArmRobot):
        c = r.ctrl
        return RobotState(rid, "arm", c.q, c.dq, c.target, extra={"scale": c.scale, "idle": bool(c._idle)})
    c = r.ctrl
    extra: dict[str, Any] = {
        "wheels": [float(w) for w in c.wheels], "wheel_speeds": [float(w) for w in c.wheel_speeds],
        "since_twist": c._since_twist, "twists_expired": c.twists_expired, "paths_done": c.paths_done,
    }
    path = np.zeros((0, 2))
    f = c.follower
    if isinstance(f, PurePursuit):
        path = f.points
        extra.update(index=f.index, stretch=f.stretch, arrived=bool(f.arrived), done=bool(f.done))
        if f.final_yaw is not None:
            extra["final_yaw"] = float(f.final_yaw)
    return RobotState(rid, "mobile", [c.x, c.y, c.yaw], [c.v, c.omega], [c.v_cmd, c.omega_cmd], path, extra)


def capture(world: SimWorld) -> tuple[float, int, tuple[RobotState, ...], tuple[ObjectInfo, ...]]:
    """(sim time, steps, robots, objects) of ``world`` now; call with the world's lock held."""
    robots = tuple(_robot_state(rid, r) for rid, r in world.robots.items())
    objects = []
    for o in world.scene.objects:
        pos, quat = world.object_pose(o.id)
        objects.append(ObjectInfo(o.id, o.kind, o.policy, pos, quat))
    return world.time, world.steps, robots, tuple(objects)


# ---------------------------------------------------------------------- restore


def _restore_robot(r: Any, s: RobotState) -> None:
    if isinstance(r, ArmRobot):
        c = r.ctrl
        if s.kind != "arm" or s.q.shape != c.q.shape:
            raise ValueError(f"robot {s.id}: state of a {s.kind} with {s.q.shape[0]} joints for an arm with {c.dof}")
        c.q = np.clip(np.array(s.q), c.lower, c.upper)
        c.dq = np.array(s.dq)
        c.target = np.clip(np.array(s.target), c.lower, c.upper)
        c.scale = float(s.extra.get("scale", 1.0))
        c._idle = False  # let the next step decide (it goes idle again at once when at the target)
        return
    c = r.ctrl
    if s.kind != "mobile" or s.q.shape != (3,):
        raise ValueError(f"robot {s.id}: state of a {s.kind} for a mobile base")
    c.x, c.y, c.yaw = (float(v) for v in s.q)
    c.v, c.omega = (float(v) for v in s.dq)
    c.v_cmd, c.omega_cmd = (float(v) for v in s.target)
    e = s.extra
    c.wheels[:] = e.get("wheels", [0.0, 0.0])
    c.wheel_speeds[:] = e.get("wheel_speeds", [0.0, 0.0])
    c._since_twist = float(e.get("since_twist", 0.0))
    c.twists_expired = int(e.get("twists_expired", 0))
    c.paths_done = int(e.get("paths_done", 0))
    c.follower = None
    if s.path.shape[0]:
        b = r.desc.base
        f = PurePursuit(s.path[:, 0], s.path[:, 1], None, max_speed=b.max_speed, max_omega=b.max_omega, max_accel=b.max_accel)
        f.final_yaw = float(e["final_yaw"]) if "final_yaw" in e else None
        f.index = min(int(e.get("index", 0)), f.points.shape[0] - 1)
        f.stretch = min(int(e.get("stretch", 0)), len(f.stops) - 1)
        f.arrived, f.done = bool(e.get("arrived", False)), bool(e.get("done", False))
        c.follower = f


def restore(world: SimWorld, state: WorldState) -> None:
    """Put ``world`` into ``state``: time, every robot's controller, every object. Robots or objects
    the state does not name keep what they have; call with the world's lock held."""
    for s in state.robots:
        r = world.robots.get(s.id)
        if r is not None:
            _restore_robot(r, s)
    for o in state.objects:
        if o.id in world.objects:
            world.set_object_pose(o.id, o.position, o.quaternion)
    world.data.time = float(state.time)
    world.steps = int(state.steps)
    world.settle()


def overlay_joints(world: SimWorld, rid: str, js: JointState) -> None:
    """An arm's joints from its stream (newer than the last snapshot): where it is and how fast it goes."""
    r = world.robots.get(rid)
    if isinstance(r, ArmRobot) and js.q.shape == r.ctrl.q.shape:
        r.ctrl.q = np.clip(np.array(js.q), r.ctrl.lower, r.ctrl.upper)
        r.ctrl.dq = np.array(js.dq)
        r.ctrl._idle = False


def overlay_pose(world: SimWorld, rid: str, pose: Pose) -> None:
    """A base's pose from its stream: position, heading and the velocities the stream carries."""
    r = world.robots.get(rid)
    if not isinstance(r, MobileRobot):
        return
    c = r.ctrl
    c.x, c.y = float(pose.position[0]), float(pose.position[1])
    w, z = float(pose.quaternion[0]), float(pose.quaternion[3])
    c.yaw = 2.0 * math.atan2(z, w)
    c.v = float(pose.linear[0] * math.cos(c.yaw) + pose.linear[1] * math.sin(c.yaw))
    c.omega = float(pose.angular[2])


def advance(world: SimWorld, lag: dict[str, float]) -> None:
    """Step each robot's controller alone by its ``lag`` (s): robots last heard at different sim times
    are brought to one time the way the primary would have moved them (the controllers are
    deterministic; the bumper and the rest of the world are not stepped for these few milliseconds)."""
    for rid, t in lag.items():
        r = world.robots.get(rid)
        n = int(round(t / world.dt)) if t > 0 else 0
        for _ in range(min(n, 5000)):
            r.before_step(world.physics)
    world.touch()
