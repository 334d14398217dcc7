"""A MuJoCo world: a scene plus robots with ids, stepped at a fixed timestep.

The scene MJCF holds the environment and the scene objects (mocap bodies);
each robot's MJCF is attached under the prefix ``"{id}/"``, so one robot type
can appear many times. Robots are kinematic, as in the paper's Unity
simulators: their controllers integrate joint and base motion and the result is
written into MuJoCo each step; MuJoCo steps the rest of the world (free bodies a
scene may add) and answers ray casts. Positions are recomputed lazily, only when
someone reads them (sensors, poses), which keeps a headless world fast.

No Zenoh here: the peer composes a World with its streams and commands.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Iterable, Sequence

import mujoco
import numpy as np

import robots as robots_pkg
from fabric.keys import validate_id
from robots import RobotDescription, SceneDescription, SceneRobot
from sim_peer.simrobot import ArmRobot, MobileRobot, SimRobot
from sim_peer.sensors import SENSED_GROUPS


BUMPER_PERIOD = 0.02  # s of sim time between bumper checks
BUMPER_HEIGHTS = (0.1, 0.4)  # m above the base: low obstacles and table tops


def _bumper_fan() -> np.ndarray:
    """Unit rays over +-75 deg around +x: the bumper looks where the base is going."""
    a = np.radians(np.linspace(-75, 75, 11))
    return np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)])


class WorldError(ValueError):
    """A world cannot be built as asked (unknown robot type, duplicate id, bad spec); the text says why."""


def parse_robot_spec(spec: str) -> SceneRobot:
    """``TYPE:ID`` or ``TYPE:ID@X,Y[,YAW[,Z]]`` (metres, degrees) -> SceneRobot (pose NaN = place automatically)."""
    head, _, where = spec.partition("@")
    rtype, sep, rid = head.partition(":")
    if not sep or not rtype or not rid:
        raise WorldError(f"robot {spec!r}: expected TYPE:ID or TYPE:ID@X,Y[,YAW_DEG[,Z]]")
    try:
        validate_id(rid, what="robot id")
    except ValueError as exc:
        raise WorldError(f"robot {spec!r}: {exc}") from None
    if not where:
        return SceneRobot(rtype, rid, (math.nan, math.nan, 0.0, 0.0))
    try:
        vals = [float(v) for v in where.split(",")]
    except ValueError:
        raise WorldError(f"robot {spec!r}: pose must be numbers X,Y[,YAW_DEG[,Z]]") from None
    if not 2 <= len(vals) <= 4 or not all(math.isfinite(v) for v in vals):
        raise WorldError(f"robot {spec!r}: pose must be 2 to 4 finite numbers X,Y[,YAW_DEG[,Z]]")
    x, y = vals[0], vals[1]
    yaw = math.radians(vals[2]) if len(vals) > 2 else 0.0
    z = vals[3] if len(vals) > 3 else 0.0
    return SceneRobot(rtype, rid, (x, y, z, yaw))


class World:
    """A scene with robots. ``step()`` advances one fixed timestep; reads are consistent after it."""

    def __init__(
        self,
        scene: SceneDescription | str = "combined",
        robots: Iterable[SceneRobot | str] = (),
        *,
        scene_robots: bool = True,
        seed: int | None = None,
        noise_std: float | None = None,
        lidar_rays: int | None = None,
        lidar_fov_deg: float | None = None,
        timestep: float | None = None,
        bumper: bool = True,
        twist_timeout: float | None = None,
    ) -> None:
        try:
            self.scene = scene if isinstance(scene, SceneDescription) else robots_pkg.scene(scene)
        except robots_pkg.DescriptionError as exc:
            raise WorldError(str(exc)) from None
        placed: list[SceneRobot] = list(self.scene.robots) if scene_robots else []
        placed += [parse_robot_spec(r) if isinstance(r, str) else r for r in robots]
        ids = [r.id for r in placed]
        for i in ids:
            try:
                validate_id(i, what="robot id")
            except ValueError as exc:
                raise WorldError(str(exc)) from None
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise WorldError(f"robot ids must be unique in a world; repeated: {', '.join(dup)}")
        clash = sorted(set(ids) & {o.id for o in self.scene.objects})
        if clash:  # one ownership namespace: robots and scene objects
            raise WorldError(f"robot id(s) {', '.join(clash)} are also scene objects of {self.scene.name}")
        self.descriptions: dict[str, RobotDescription] = {}
        for r in placed:
            try:
                desc = robots_pkg.load(r.type)
            except robots_pkg.DescriptionError as exc:
                raise WorldError(str(exc)) from None
            if desc.lidar is not None and (lidar_rays is not None or lidar_fov_deg is not None or noise_std is not None):
                lid = desc.lidar
                if lidar_rays is not None:
                    if not 1 <= lidar_rays <= 4096:
                        raise WorldError(f"lidar rays must be in 1..4096, got {lidar_rays}")
                    lid = replace(lid, rays=int(lidar_rays))
                if lidar_fov_deg is not None:
                    if not 0 < lidar_fov_deg <= 360:
                        raise WorldError(f"lidar field of view must be in (0, 360] deg, got {lidar_fov_deg}")
                    lid = replace(lid, fov=math.radians(lidar_fov_deg))
                if noise_std is not None:
                    lid = replace(lid, noise_std=float(noise_std))
                desc = replace(desc, lidar=lid)
            if desc.ultrasonic is not None and noise_std is not None:
                desc = replace(desc, ultrasonic=replace(desc.ultrasonic, noise_std=float(noise_std)))
            self.descriptions[r.id] = desc
        if twist_timeout is not None and not twist_timeout > 0:
            raise WorldError(f"twist timeout must be positive, got {twist_timeout}")
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        placed = self._place(placed)
        self.placements = {r.id: r for r in placed}

        spec = mujoco.MjSpec.from_file(str(self.scene.mjcf_path))
        for r in placed:
            desc = self.descriptions[r.id]
            child = mujoco.MjSpec.from_file(str(desc.mjcf_path))
            x, y, z, yaw = r.pose
            if desc.kind == "mobile":
                frame = spec.worldbody.add_frame(pos=[0.0, 0.0, z])  # base joints carry x, y, yaw
            else:
                frame = spec.worldbody.add_frame(pos=[x, y, z], quat=[math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
            root = child.body(desc.root_body)
            if root is None:
                raise WorldError(f"robot type {desc.name}: root body {desc.root_body!r} is not in {desc.mjcf_path}")
            frame.attach_body(root, f"{r.id}/", "")
        try:
            self.model = spec.compile()
        except Exception as exc:  # MuJoCo compile errors are plain ValueErrors with the XML detail
            raise WorldError(f"scene {self.scene.name}: {exc}") from None
        self.model.opt.timestep = float(timestep or self.scene.timestep)
        self.data = mujoco.MjData(self.model)
        self.dt = float(self.model.opt.timestep)

        self.robots: dict[str, SimRobot] = {}
        for r in placed:
            desc = self.descriptions[r.id]
            if desc.kind == "arm":
                self.robots[r.id] = ArmRobot(r.id, desc, self.model, f"{r.id}/")
            else:
                x, y, z, yaw = r.pose
                self.robots[r.id] = MobileRobot(r.id, desc, self.model, f"{r.id}/", (x, y, yaw), self.rng, twist_timeout)
        self.objects: dict[str, int] = {}
        for o in self.scene.objects:
            bid = self.model.body(o.body).id if _has_body(self.model, o.body) else -1
            mocap = int(self.model.body_mocapid[bid]) if bid >= 0 else -1
            if mocap < 0:
                raise WorldError(f"scene {self.scene.name}: object {o.id!r} needs a mocap body named {o.body!r}")
            self.objects[o.id] = mocap
        self.object_home = {o: (self.data.mocap_pos[i].copy(), self.data.mocap_quat[i].copy()) for o, i in self.objects.items()}
        robot_dofs = sum(len(r.vadr) for r in self.robots.values())
        self.dynamic = self.model.nv > robot_dofs  # free bodies or other joints beyond the robots' own: step them
        for r in self.robots.values():
            r._dynamic = self.dynamic
        self.steps = 0
        self.bumper = bumper
        self.collisions: list[tuple[str, float]] = []  # (robot id, sim time) of bumper stops, for the peer to report
        self._bump_every = max(1, int(round(BUMPER_PERIOD / self.dt)))
        self._bump_dirs = _bumper_fan()
        self._bump_gid = np.zeros(len(self._bump_dirs), np.int32)
        self._bump_dist = np.zeros(len(self._bump_dirs))
        self._apply()
        mujoco.mj_forward(self.model, self.data)
        self._dirty = False

    # ------------------------------------------------------------------ building

    def _place(self, placed: list[SceneRobot]) -> list[SceneRobot]:
        """Give robots without a pose a free spot: a square spiral from the first robot's spot, 0.8 m apart."""
        if not any(math.isnan(r.pose[0]) for r in placed):
            return placed
        probe = mujoco.MjModel.from_xml_path(str(self.scene.mjcf_path))
        pd = mujoco.MjData(probe)
        mujoco.mj_forward(probe, pd)
        taken = [(r.pose[0], r.pose[1], self.descriptions[r.id].base_radius or 0.3) for r in placed if not math.isnan(r.pose[0])]
        mobile = [r for r in placed if not math.isnan(r.pose[0]) and self.descriptions[r.id].kind == "mobile"]
        ox, oy = (mobile[0].pose[0], mobile[0].pose[1]) if mobile else (0.0, 0.0)
        dirs = np.array([[math.cos(a), math.sin(a), 0.0] for a in np.linspace(0, 2 * math.pi, 24, endpoint=False)]).reshape(-1)
        gid, dist = np.zeros(24, np.int32), np.zeros(24)
        out = []
        cells = _spiral(400)
        for r in placed:
            if not math.isnan(r.pose[0]):
                out.append(r)
                continue
            radius = self.descriptions[r.id].base_radius or 0.3
            for i, j in cells:
                x, y = ox + 0.8 * i, oy + 0.8 * j
                if any(math.hypot(x - tx, y - ty) < radius + tr + 0.05 for tx, ty, tr in taken):
                    continue
                free = True
                for h in (0.05, 0.3, 0.8):
                    mujoco.mj_multiRay(probe, pd, np.array([x, y, h]), dirs, SENSED_GROUPS, 1, -1, gid, dist, None, 24, radius + 0.1)
                    if ((dist >= 0) & (dist < radius + 0.1)).any():  # cutoff is only a bounding-sphere filter
                        free = False
                        break
                if free:
                    taken.append((x, y, radius))
                    out.append(SceneRobot(r.type, r.id, (x, y, r.pose[2], r.pose[3])))
                    break
            else:
                raise WorldError(f"no free spot found for robot {r.id}; give it a pose with TYPE:ID@X,Y")
        return out

    # ------------------------------------------------------------------ stepping

    @property
    def time(self) -> float:
        return float(self.data.time)

    def _apply(self) -> None:
        for r in self.robots.values():
            r.apply(self.data)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` fixed timesteps: controllers, then MuJoCo for everything else."""
        dt = self.dt
        m, d = self.model, self.data
        for _ in range(n):
            for r in self.robots.values():
                r.step(dt)
            if self.dynamic:
                mujoco.mj_step(m, d)  # the rest of the world, against the robots where they were
            else:
                d.time += dt  # nothing but kinematic robots and mocap markers: no dynamics to integrate
            self._apply()  # robots are kinematic: their controllers, not dynamics, say where they are
            self.steps += 1
            if self.bumper and self.steps % self._bump_every == 0:
                self._bump()
        self._dirty = True

    def _bump(self) -> None:
        """Stop a base that is about to drive into something (a ray bumper ahead of its direction of travel)."""
        reach_time = self._bump_every * self.dt
        for rid, r in self.robots.items():
            if not isinstance(r, MobileRobot) or abs(r.ctrl.v) < 1e-6:
                continue
            c = r.ctrl
            spec = r.desc.ultrasonic
            cx, cy = spec.center if spec is not None else (0.0, 0.0)
            shell = spec.radius if spec is not None else r.desc.base_radius
            cos, sin = math.cos(c.yaw), math.sin(c.yaw)
            heading = c.yaw if c.v > 0 else c.yaw + math.pi
            ch, sh = math.cos(heading), math.sin(heading)
            vec = (self._bump_dirs @ np.array([[ch, sh, 0.0], [-sh, ch, 0.0], [0.0, 0.0, 1.0]])).reshape(-1)
            origin = np.array([c.x + cos * cx - sin * cy, c.y + sin * cx + cos * cy, 0.0])
            reach = shell + abs(c.v) * reach_time + 0.01
            for h in BUMPER_HEIGHTS:
                origin[2] = h
                mujoco.mj_multiRay(
                    self.model, self.data, origin, vec, SENSED_GROUPS, 1, r.body_id,
                    self._bump_gid, self._bump_dist, None, len(self._bump_gid), reach,
                )
                if ((self._bump_dist >= 0) & (self._bump_dist < reach)).any():
                    c.stop()
                    self.collisions.append((rid, self.time))
                    break

    def sync(self) -> None:
        """Make positions (bodies, sites) match the current state; cheap when nothing changed."""
        if self._dirty:
            mujoco.mj_kinematics(self.model, self.data)
            mujoco.mj_comPos(self.model, self.data)  # for Jacobians (flange velocity)
            self._dirty = False

    def reset(self) -> None:
        """Everything back to its initial state at time 0."""
        mujoco.mj_resetData(self.model, self.data)
        for r in self.robots.values():
            if isinstance(r, ArmRobot):
                r.ctrl.teleport(np.zeros(r.ctrl.dof))
            else:
                r.ctrl.reset()
        for o, i in self.objects.items():
            self.data.mocap_pos[i], self.data.mocap_quat[i] = self.object_home[o]
        self.steps = 0
        self._apply()
        mujoco.mj_forward(self.model, self.data)
        self._dirty = False

    # ------------------------------------------------------------------ robots and objects

    def robot(self, robot_id: str) -> SimRobot:
        try:
            return self.robots[robot_id]
        except KeyError:
            raise KeyError(f"unknown robot {robot_id!r}; this world has {', '.join(self.robots) or 'none'}") from None

    def moving(self) -> dict[str, bool]:
        return {rid: r.moving for rid, r in self.robots.items()}

    def set_object_pose(self, obj: str, position: Sequence[float], quaternion: Sequence[float] | None = None) -> None:
        if obj not in self.objects:
            raise KeyError(f"unknown scene object {obj!r}; this scene has {', '.join(self.objects) or 'none'}")
        i = self.objects[obj]
        p = np.asarray(position, dtype=np.float64)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError("object position must be 3 finite numbers")
        self.data.mocap_pos[i] = p
        if quaternion is not None:
            q = np.asarray(quaternion, dtype=np.float64)
            n = float(np.linalg.norm(q))
            if q.shape != (4,) or not np.isfinite(q).all() or n < 1e-9:
                raise ValueError("object quaternion must be 4 finite numbers, not all zero")
            self.data.mocap_quat[i] = q / n
        self._dirty = True

    def object_pose(self, obj: str) -> tuple[np.ndarray, np.ndarray]:
        i = self.objects[obj]
        return self.data.mocap_pos[i].copy(), self.data.mocap_quat[i].copy()

    def scan(self, robot_id: str) -> np.ndarray:
        r = self.robot(robot_id)
        if not isinstance(r, MobileRobot) or r.lidar is None:
            raise KeyError(f"robot {robot_id!r} has no LIDAR")
        self.sync()
        return r.lidar.read(self.data)

    def sonar(self, robot_id: str) -> np.ndarray:
        r = self.robot(robot_id)
        if not isinstance(r, MobileRobot) or r.sonar is None:
            raise KeyError(f"robot {robot_id!r} has no ultrasonic ring")
        self.sync()
        return r.sonar.read(self.data)

    def flange(self, robot_id: str) -> tuple[np.ndarray, np.ndarray]:
        """Flange position and quaternion (w, x, y, z) of an arm, world frame."""
        r = self.robot(robot_id)
        if not isinstance(r, ArmRobot):
            raise KeyError(f"robot {robot_id!r} is not an arm")
        self.sync()
        return r.flange(self.data)

    def flange_velocity(self, robot_id: str) -> tuple[np.ndarray, np.ndarray]:
        """Flange linear and angular velocity of an arm, world frame (J(q) dq)."""
        r = self.robot(robot_id)
        if not isinstance(r, ArmRobot):
            raise KeyError(f"robot {robot_id!r} is not an arm")
        self.sync()
        return r.flange_velocity(self.data)

    def state(self, robot_id: str) -> dict[str, Any]:
        """A robot's last known state as a small dict of plain values (for the ownership record)."""
        self.sync()
        out = self.robot(robot_id).state(self.data)
        out["t"] = self.time
        return out


def _has_body(model: mujoco.MjModel, name: str) -> bool:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) >= 0


def _spiral(n: int) -> list[tuple[int, int]]:
    """Grid cells in a square spiral from (0, 0)."""
    cells = [(0, 0)]
    x = y = 0
    dx, dy = 1, 0
    leg = 1
    while len(cells) < n:
        for _ in range(2):
            for _ in range(leg):
                x, y = x + dx, y + dy
                cells.append((x, y))
            dx, dy = -dy, dx
        leg += 1
    return cells[:n]
