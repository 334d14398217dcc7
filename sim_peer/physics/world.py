"""A simulated world: a scene plus robots with ids, stepped at a fixed timestep.

The scene MJCF holds the environment and the scene objects (mocap bodies); each robot's MJCF is attached
under the prefix ``"{id}/"`` (:mod:`sim_peer.physics.build`), so one robot type can appear many times; robots
given without a pose get a free spot (:mod:`sim_peer.physics.placement`). Robots are kinematic, as in the paper's
Unity simulators: each step, every robot's ``before_step`` hook advances its controllers, MuJoCo steps the
rest of the world (free bodies a scene may add; skipped when there is none), and every robot's
``after_step`` writes its state into MuJoCo and runs its sensors' checks (the bumper,
:mod:`sim_peer.bumper`). Positions are recomputed lazily, only when someone reads them (sensors, poses),
which keeps a headless world fast (:mod:`sim_peer.physics.positions`).

The world is the composition root of its parts, each in its own module: ``notes`` (what robots said, until
the peer takes it: :mod:`sim_peer.physics.notes`), ``objects`` (the scene objects' poses: :mod:`sim_peer.physics.scene_objects`),
``mirrors`` (other sims' robots its sensors see: :mod:`sim_peer.physics.mirrors`) and ``readings`` (sensor reads on
demand: :mod:`sim_peer.physics.readings`). The world itself steps, resets and finds robots.

Named ``SimWorld`` (not ``World``): the user API's :class:`user_peer.World` is a user's view of a world.
No Zenoh here: the peer composes a SimWorld with its streams and commands.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import mujoco
import numpy as np

from robots import SceneDescription, SceneRobot
from sim_peer.physics.build import SensorOptions, compile_model, load_scene, resolve, scene_objects
from sim_peer.physics.errors import WorldError
from sim_peer.physics.mirrors import Mirrors, Shape
from sim_peer.physics.notes import NoteLog
from sim_peer.physics.placement import parse_robot_spec, place
from sim_peer.physics.positions import Positions
from sim_peer.physics.readings import Readings
from sim_peer.physics.registry import robot_class
from sim_peer.robot import Mount, Physics, SimRobot
from sim_peer.physics.scene_objects import SceneObjects
from sim_peer.physics.traffic import Traffic

MAX_MIRRORS = 256  # mirror slots a world may have (each costs every ray a bounding-sphere test)


class SimWorld:
    """A scene with robots. ``step()`` advances fixed timesteps; reads are consistent after it."""

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
        mirrors: int = 0,
    ) -> None:
        self.scene = load_scene(scene)
        options = SensorOptions(noise_std=noise_std, lidar_rays=lidar_rays, lidar_fov_deg=lidar_fov_deg)
        placed, self.descriptions = resolve(self.scene, robots, scene_robots=scene_robots, options=options)
        classes = {rid: robot_class(d) for rid, d in self.descriptions.items()}
        if twist_timeout is not None and not twist_timeout > 0:
            raise WorldError(f"twist timeout must be positive, got {twist_timeout}")
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        placed = place(self.scene.mjcf_path, placed, self.descriptions)
        self.placements: dict[str, SceneRobot] = {r.id: r for r in placed}

        if not 0 <= mirrors <= MAX_MIRRORS:
            raise WorldError(f"mirror slots must be within 0..{MAX_MIRRORS}, got {mirrors}")
        self.model = compile_model(self.scene, placed, self.descriptions, mirrors=mirrors)
        self.model.opt.timestep = float(timestep or self.scene.timestep)
        self.data = mujoco.MjData(self.model)
        self.dt = float(self.model.opt.timestep)
        self.bumper = bumper
        self.notes = NoteLog()  # what robots and sensors said, until the peer takes it
        self.traffic = Traffic()  # where the bases stand and who waits for whom: their way guards' board
        self.robots: dict[str, SimRobot] = {
            r.id: classes[r.id](
                Mount(
                    r.id,
                    self.descriptions[r.id],
                    self.model,
                    r.pose,
                    self.rng,
                    self.notes.add,
                    twist_timeout,
                    bumper,
                    self.traffic,
                )
            )
            for r in placed
        }
        self.positions = Positions(self.model, self.data)
        self.objects = SceneObjects(self.data, scene_objects(self.model, self.scene), self.positions)
        self.mirrors = Mirrors(self.model, self.data)  # robots other sims of the world simulate, for the sensors
        self.readings = Readings(self.robot, self.data, self.positions)
        robot_dofs = sum(r.kinematic_dofs for r in self.robots.values())
        # free bodies or other joints beyond the robots' own: MuJoCo steps them; else only the robots move
        self.physics = Physics(self.model, self.data, self.dt, dynamic=self.model.nv > robot_dofs)
        self._before = tuple(r.before_step for r in self.robots.values())
        self._after = tuple(r.after_step for r in self.robots.values())
        self._after_all()
        self.positions.forward()

    # ------------------------------------------------------------------ stepping

    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def steps(self) -> int:
        return self.physics.steps

    @steps.setter
    def steps(self, n: int) -> None:
        self.physics.steps = int(n)

    @property
    def dynamic(self) -> bool:
        return self.physics.dynamic

    def _after_all(self) -> None:
        for hook in self._after:
            hook(self.physics)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` fixed timesteps: robots' controllers, then MuJoCo for everything else, then robots' state."""
        physics, before, after = self.physics, self._before, self._after
        m, d, dt = self.model, self.data, self.dt
        dynamic = physics.dynamic
        physics.stepping = True
        for _ in range(n):
            for hook in before:
                hook(physics)
            if dynamic:
                mujoco.mj_step(m, d)  # the rest of the world, against the robots where they were
            else:
                d.time += dt  # nothing but kinematic robots and mocap markers: no dynamics to integrate
            physics.steps += 1
            for hook in after:  # robots are kinematic: their controllers, not dynamics, say where they are
                hook(physics)
        physics.stepping = False
        self.positions.mark()

    def settle(self) -> None:
        """After robots' controllers were changed from outside (a restored state): write them into MuJoCo and
        recompute positions now."""
        self._after_all()
        self.positions.forward()

    def touch(self) -> None:
        """After robots' controllers were stepped from outside: write them into MuJoCo; positions on next read."""
        self._after_all()
        self.positions.mark()

    def sync(self) -> None:
        """Make positions (bodies, sites) match the current state; cheap when nothing changed."""
        self.positions.sync()

    def reset(self) -> None:
        """Everything back to its initial state at time 0."""
        mujoco.mj_resetData(self.model, self.data)
        for r in self.robots.values():
            r.initialize(self.physics)
        self.objects.reset()
        self.physics.steps = 0
        self.settle()

    # ------------------------------------------------------------------ robots and mirrors

    def robot(self, robot_id: str) -> Any:
        try:
            return self.robots[robot_id]
        except KeyError:
            raise KeyError(f"unknown robot {robot_id!r}; this world has {', '.join(self.robots) or 'none'}") from None

    def moving(self) -> dict[str, bool]:
        return {rid: r.moving for rid, r in self.robots.items()}

    def mirror(
        self,
        robot_id: str,
        *,
        radius: float,
        height: float,
        position: Sequence[float],
        quaternion: Sequence[float],
        source: str = "",
    ) -> bool:
        """Show a robot that ``source``, another sim of the world, simulates, where that sim says it is, so this
        sim's sensors see it (:mod:`sim_peer.physics.mirrors`); False when no slot is free, the pose is not finite, or
        the robot is one of this world's own."""
        if robot_id in self.robots or self.mirrors.show(robot_id, radius, height, source) is None:
            return False
        placed = self.mirrors.place(robot_id, position, quaternion)
        self.positions.mark()
        return placed

    def mirror_shapes(
        self,
        robot_id: str,
        shapes: Sequence[Shape],
        poses: Sequence[tuple[Sequence[float], Sequence[float]]],
        *,
        source: str = "",
    ) -> bool:
        """Show a robot of another sim as several geoms (an arm's links: :mod:`sim_peer.physics.arm_mirror`), each at
        its pose; False when too few slots are free, a pose is not finite, or the robot is this world's own."""
        if robot_id in self.robots or self.mirrors.show_shapes(robot_id, shapes, source) is None:
            return False
        placed = self.mirrors.place_shapes(robot_id, poses)
        self.positions.mark()
        return placed

    def unmirror(self, robot_id: str | None = None, *, source: str | None = None) -> list[str]:
        """Hide one mirrored robot, or every robot ``source`` simulated (that sim left); the ids hidden."""
        gone = ([robot_id] if robot_id is not None and self.mirrors.hide(robot_id) else []) + (
            self.mirrors.hide_from(source) if source is not None else []
        )
        if gone:
            self.positions.mark()
        return gone

    def state(self, robot_id: str) -> dict[str, Any]:
        """A robot's last known state as a small dict of plain values (for the ownership record)."""
        self.sync()
        out = self.robot(robot_id).state(self.physics)
        out["t"] = self.time
        return out


__all__ = ["SimWorld", "WorldError", "parse_robot_spec"]
