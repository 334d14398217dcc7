"""Kinematic controllers: joint position control for arms, twist control for differential-drive bases.

Pure numpy, no MuJoCo and no Zenoh: inputs are commands and a time step,
outputs are the new joint positions and velocities. The world writes them into
MuJoCo; tests drive them directly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fabric.interfaces import EventKind, sample_trajectory, wrap_angle
from robots import BaseSpec

MOVING_JOINT_SPEED = 1e-3  # rad/s: above this a joint counts as moving (the ownership gate's "in motion")
MOVING_BASE_SPEED = 1e-3  # m/s and rad/s
DEFAULT_TWIST_TIMEOUT = 0.5
"""Seconds of real time a served base keeps a twist without a fresh one (the ROS teleop deadman): a client
that drives repeats its twist well within it (the user API at 10 Hz), so a base whose driver went quiet
(closed her laptop, crashed, lost the network) brakes to a halt. ``robofabric sim --twist-timeout``."""
ABSURD_FACTOR = 5.0  # a twist above this multiple of the robot's limits is refused, not clamped


class CommandRejected(ValueError):
    """A command the robot cannot take at all; ``reason`` is a short machine-friendly tag, the text says why."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


@dataclass(frozen=True, slots=True)
class Clamp:
    """What a command asked for outside the robot's limits and what was applied instead."""

    what: tuple[str, ...]
    requested: tuple[float, ...]
    applied: tuple[float, ...]


def _finite_vector(values, n: int, what: str) -> np.ndarray:
    try:
        q = np.asarray(values, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise CommandRejected("bad_value", f"{what} must be numbers") from None
    if q.shape[0] != n:
        raise CommandRejected("wrong_joint_count", f"{what} has {q.shape[0]} values, the robot has {n} joints")
    if not np.isfinite(q).all():
        raise CommandRejected("not_finite", f"{what} contains NaN or infinity")
    return q


@dataclass(slots=True)
class Playing:
    """A joint trajectory an arm plays: the joints when it began, its points (clamped to the range), and the sim's
    time since it began."""

    start: np.ndarray
    times: np.ndarray
    positions: np.ndarray
    elapsed: float = 0.0

    @property
    def goal(self) -> np.ndarray:
        return self.positions[-1]


class ArmController:
    """Moves joints toward a target in a straight line in joint space, no joint faster than its limit.

    All joints start and arrive together (the slowest joint sets the pace), like a
    robot controller's joint move. Targets outside the range are clamped to it.

    A trajectory (:meth:`set_trajectory`) moves the target along timed points in the sim's time, step by step, so
    the arm keeps the trajectory's timing however late its sender is (within the joints' speed limits).
    """

    def __init__(self, names, lower, upper, max_speed) -> None:
        self.names = tuple(names)
        self.lower = np.asarray(lower, dtype=np.float64)
        self.upper = np.asarray(upper, dtype=np.float64)
        self.max_speed = np.asarray(max_speed, dtype=np.float64)
        n = len(self.names)
        self.q = np.clip(np.zeros(n), self.lower, self.upper)
        self.dq = np.zeros(n)
        self.target = self.q.copy()
        self.scale = 1.0
        self._idle = False
        self.playing: Playing | None = None

    @property
    def dof(self) -> int:
        return len(self.names)

    @property
    def idle(self) -> bool:
        """At the target and at rest since the last step: stepping changes nothing until the next command."""
        return self._idle

    def set_target(self, q, speed_scale: float = 1.0) -> Clamp | None:
        """Aim at ``q``; raise :class:`CommandRejected` for a wrong length or non-finite values; report clamps."""
        q = _finite_vector(q, self.dof, "joint target")
        if not (math.isfinite(speed_scale) and 0 < speed_scale <= 1):
            raise CommandRejected("bad_speed_scale", f"speed_scale must be in (0, 1], got {speed_scale}")
        applied = np.clip(q, self.lower, self.upper)
        self.target = applied
        self._idle = False
        self.scale = float(speed_scale)
        self.playing = None
        bad = np.flatnonzero(applied != q)
        if bad.size == 0:
            return None
        return Clamp(
            tuple(self.names[i] for i in bad), tuple(float(q[i]) for i in bad), tuple(float(applied[i]) for i in bad)
        )

    def set_trajectory(self, times, positions) -> Clamp | None:
        """Play ``positions[i]`` at ``times[i]`` s from now (from where the joints are, linearly between points, at
        the speed limits); :class:`CommandRejected` for points of the wrong width, not finite, or times that go back.
        Points outside the range are clamped to it (reported, each joint's furthest)."""
        try:
            t = np.asarray(times, dtype=np.float64).reshape(-1)
            pts = np.asarray(positions, dtype=np.float64)
        except (TypeError, ValueError):
            raise CommandRejected("bad_value", "a trajectory's times and positions must be numbers") from None
        if pts.ndim != 2 or pts.shape[1] != self.dof or pts.shape[0] != t.shape[0] or t.shape[0] == 0:
            raise CommandRejected(
                "wrong_joint_count",
                f"a trajectory of {t.shape[0]} times needs as many points of {self.dof} joints, got {pts.shape}",
            )
        if not (np.isfinite(t).all() and np.isfinite(pts).all()):
            raise CommandRejected("not_finite", "a trajectory's times or positions contain NaN or infinity")
        if t[0] < 0 or (np.diff(t) < 0).any():
            raise CommandRejected("bad_value", "a trajectory's times must start at 0 or later and not decrease")
        applied = np.clip(pts, self.lower, self.upper)
        self.playing = Playing(self.q.copy(), t, applied)
        self.scale = 1.0
        self._idle = False
        off = np.abs(applied - pts)
        bad = np.flatnonzero(off.max(axis=0) > 0)
        if bad.size == 0:
            return None
        rows = off.argmax(axis=0)
        return Clamp(
            tuple(self.names[j] for j in bad),
            tuple(float(pts[rows[j], j]) for j in bad),
            tuple(float(applied[rows[j], j]) for j in bad),
        )

    @property
    def goal(self) -> np.ndarray:
        """Where the joints are headed: the trajectory's last point while one plays, else the target (what a
        standby that takes the arm over is given: it goes there at the speed limits, not along the trajectory)."""
        return self.playing.goal.copy() if self.playing is not None else self.target.copy()

    def stop(self) -> None:
        """Hold where the joints are now."""
        self.playing = None
        self.target = self.q.copy()
        self.dq = np.zeros(self.dof)
        self._idle = False

    def reset(self) -> None:
        """Go back to zero (within range), at the speed limits."""
        self.playing = None
        self.target = np.clip(np.zeros(self.dof), self.lower, self.upper)
        self.scale = 1.0
        self._idle = False

    def teleport(self, q) -> None:
        """Put the joints at ``q`` at once (clamped), holding there: for restoring a known state."""
        self.q = np.clip(np.asarray(q, dtype=np.float64), self.lower, self.upper)
        self.playing = None
        self.target = self.q.copy()
        self.dq = np.zeros(self.dof)
        self._idle = False

    def restore(self, q, dq, target=None, scale: float | None = None) -> None:
        """Joints at ``q`` moving at ``dq`` (a replicated state: positions and targets clamped to the range);
        the next step decides whether it is at rest."""
        self.q = np.clip(np.array(q, dtype=np.float64), self.lower, self.upper)
        self.dq = np.array(dq, dtype=np.float64)
        if target is not None:  # a whole state (a mirror's joints alone leave a trajectory playing)
            self.playing = None
            self.target = np.clip(np.array(target, dtype=np.float64), self.lower, self.upper)
        if scale is not None:
            self.scale = float(scale)
        self._idle = False

    def step(self, dt: float) -> None:
        if self._idle:
            return
        p = self.playing
        if p is not None:
            p.elapsed += dt
            desired, over = sample_trajectory(p.times, p.positions, p.start, p.elapsed)
            self.target = np.clip(desired, self.lower, self.upper)
            if over:
                self.playing = None
        err = self.target - self.q
        vmax = self.max_speed * self.scale
        duration = float(np.max(np.abs(err) / vmax)) if err.size else 0.0
        if duration <= dt:
            self.dq = err / dt if duration > 0 else np.zeros_like(err)
            self.q = self.target.copy()
            # at the target and at rest: nothing to do until the next command (a trajectory holding still goes on)
            self._idle = duration == 0 and self.playing is None
        else:
            self.dq = err / duration
            self.q = self.q + self.dq * dt

    @property
    def moving(self) -> bool:
        """Joints faster than :data:`MOVING_JOINT_SPEED`, or a trajectory still playing (one that holds a point for a
        while is not still: the ownership gate's takeover waits for its end)."""
        return self.playing is not None or bool(np.any(np.abs(self.dq) > MOVING_JOINT_SPEED))


class BaseController:
    """A differential-drive base driven by (v, omega), with speed and acceleration limits.

    A twist holds until the next command, or, with ``twist_timeout``, until that much sim
    time passes without a fresh twist (a dead-man for teleoperation over a network: the sim
    peer's default, docs/sim.md); the base then brakes within its acceleration limits.

    The pose (x, y, yaw) is that of the midpoint of the wheel axle, the point the
    base turns about; an in-place turn leaves it where it is. A path follower, when
    set, supplies the desired twist each step instead of the last twist command.
    """

    def __init__(
        self,
        spec: BaseSpec,
        pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
        *,
        twist_timeout: float | None = None,
        on_news: Callable[[EventKind], None] | None = None,
    ) -> None:
        self.spec = spec
        self.on_news = on_news  # told EventKind.PATH_DONE or TWIST_TIMEOUT when they happen (no cost per step)
        self.twist_timeout = (
            twist_timeout  # s of sim time a twist holds without a fresh one (None: until told otherwise)
        )
        self._since_twist = 0.0
        self.twists_expired = 0
        self.home = tuple(float(p) for p in pose)
        self.x, self.y, self.yaw = self.home
        self.v = 0.0
        self.omega = 0.0
        self.v_cmd = 0.0
        self.omega_cmd = 0.0
        self.wheels = np.zeros(2)  # left, right wheel angles (rad)
        self.wheel_speeds = np.zeros(2)
        self.follower = None  # anything with step(x, y, yaw, v, dt) -> (v, omega, done)
        self.speed_cap = (
            math.inf
        )  # m/s a path follower may drive at: set by the base's way guard (sim_peer.physics.way_guard)
        self.paths_done = 0  # paths followed to their end (not stopped or replaced)

    def twist(self, v: float, omega: float) -> Clamp | None:
        """Drive at (v, omega) until told otherwise; absurd values are refused, excessive ones clamped."""
        s = self.spec
        if not (math.isfinite(v) and math.isfinite(omega)):
            raise CommandRejected("not_finite", "twist contains NaN or infinity")
        if abs(v) > ABSURD_FACTOR * s.max_speed or abs(omega) > ABSURD_FACTOR * s.max_omega:
            raise CommandRejected(
                "absurd_twist",
                f"twist ({v:g} m/s, {omega:g} rad/s) is beyond {ABSURD_FACTOR:g}x the limits ({s.max_speed:g} m/s, {s.max_omega:g} rad/s)",
            )
        self.follower = None
        self._since_twist = 0.0
        av = max(-s.max_speed, min(s.max_speed, v))
        aw = max(-s.max_omega, min(s.max_omega, omega))
        self.v_cmd, self.omega_cmd = av, aw
        if (av, aw) == (v, omega):
            return None
        names, req, app = [], [], []
        if av != v:
            names.append("v"), req.append(v), app.append(av)
        if aw != omega:
            names.append("omega"), req.append(omega), app.append(aw)
        return Clamp(tuple(names), tuple(req), tuple(app))

    def follow(self, follower) -> None:
        self.follower = follower

    @property
    def since_twist(self) -> float:
        """Sim time (s) the current twist has held without a fresh one: what ``twist_timeout`` is counted on."""
        return self._since_twist

    def resume_twist_clock(self, since: float) -> None:
        """Carry on a replicated count: ``since`` s have passed since the last twist (a standby taking over), so
        a twist times out here when it would have on the sim that sent it."""
        self._since_twist = float(since)

    def stop(self) -> None:
        """Stop at once and forget any path."""
        self.follower = None
        self.v_cmd = self.omega_cmd = 0.0
        self.v = self.omega = 0.0
        self.wheel_speeds[:] = 0.0

    def brake(self) -> None:
        """Forget the twist and any path and slow to a halt within the acceleration limits (its owner let go:
        a real base cannot stop in one step, and a velocity jump is what a safety review refuses)."""
        self.follower = None
        self.v_cmd = self.omega_cmd = 0.0

    def reset(self) -> None:
        """Back to the spawn pose, at rest."""
        self.stop()
        self.x, self.y, self.yaw = self.home

    def teleport(self, x: float, y: float, yaw: float) -> None:
        self.stop()
        self.x, self.y, self.yaw = float(x), float(y), wrap_angle(float(yaw))

    def step(self, dt: float) -> None:
        if self.follower is None and not (self.v or self.omega or self.v_cmd or self.omega_cmd):
            self.wheel_speeds[:] = 0.0
            return  # at rest with nothing to do
        s = self.spec
        if self.follower is not None:
            v_d, w_d, done = self.follower.step(self.x, self.y, self.yaw, self.v, dt)
            if done:
                quiet = getattr(
                    self.follower, "quiet", False
                )  # a way guard's own move (backing off): not the user's path
                self.follower = None
                self.paths_done += not quiet
                if self.on_news is not None and not quiet:
                    self.on_news(EventKind.PATH_DONE)
                v_d = w_d = 0.0
            v_d = max(-self.speed_cap, min(self.speed_cap, v_d))  # something in its way: slow, or wait
            self.v_cmd, self.omega_cmd = v_d, w_d
        elif self.twist_timeout is not None and (self.v_cmd or self.omega_cmd):
            self._since_twist += dt
            if self._since_twist > self.twist_timeout:  # the sender went quiet: slow to a halt
                self.v_cmd = self.omega_cmd = 0.0
                self.twists_expired += 1
                if self.on_news is not None:
                    self.on_news(EventKind.TWIST_TIMEOUT)
        dv = max(-s.max_accel * dt, min(s.max_accel * dt, self.v_cmd - self.v))
        dw = max(-s.max_alpha * dt, min(s.max_alpha * dt, self.omega_cmd - self.omega))
        self.v += dv
        self.omega += dw
        v, w = self.v, self.omega
        if abs(w) > 1e-9:
            r = v / w
            self.x += r * (math.sin(self.yaw + w * dt) - math.sin(self.yaw))
            self.y -= r * (math.cos(self.yaw + w * dt) - math.cos(self.yaw))
        else:
            self.x += v * dt * math.cos(self.yaw)
            self.y += v * dt * math.sin(self.yaw)
        self.yaw = wrap_angle(self.yaw + w * dt)
        half = s.wheel_separation / 2
        self.wheel_speeds[0] = (v - w * half) / s.wheel_radius
        self.wheel_speeds[1] = (v + w * half) / s.wheel_radius
        self.wheels += self.wheel_speeds * dt

    @property
    def moving(self) -> bool:
        return abs(self.v) > MOVING_BASE_SPEED or abs(self.omega) > MOVING_BASE_SPEED or self.follower is not None

    def pose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Position, quaternion (w, x, y, z), linear and angular velocity of the axle midpoint, world frame
        (what the base's ``pose`` stream carries)."""
        pos = np.array([self.x, self.y, 0.0])
        quat = np.array([math.cos(self.yaw / 2), 0.0, 0.0, math.sin(self.yaw / 2)])
        lin = np.array([self.v * math.cos(self.yaw), self.v * math.sin(self.yaw), 0.0])
        ang = np.array([0.0, 0.0, self.omega])
        return pos, quat, lin, ang
