"""A ray bumper: stops a differential-drive base that is about to drive into something.

Every ``BUMPER_PERIOD`` of sim time, a fan of rays (+-75 deg around the direction of travel, at two heights:
low obstacles and table tops) is cast from the base's shell; a hit within the distance the base covers
before the next check stops it and says so (a ``collision`` note, published by the peer as
``Event(kind=EventKind.COLLISION, reason="bumper")``). A sensor of the robot that holds it (:mod:`sim_peer.robot`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from fabric.interfaces import EventKind
from sim_peer.robot import Note, Physics
from sim_peer.sensors import SENSED_GROUPS, Sensor

if TYPE_CHECKING:
    from sim_peer.physics.robot_kinds import MobileRobot

BUMPER_PERIOD = 0.02  # s of sim time between bumper checks
BUMPER_HEIGHTS = (0.1, 0.4)  # m above the base: low obstacles and table tops


def _bumper_fan() -> np.ndarray:
    """Unit rays over +-75 deg around +x: the bumper looks where the base is going."""
    a = np.radians(np.linspace(-75, 75, 11))
    return np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)])


class Bumper(Sensor):
    """The bumper of one mobile robot; checks on the steps that are multiples of ``BUMPER_PERIOD / dt``."""

    def __init__(self, robot: MobileRobot, dt: float) -> None:
        self.robot = robot
        self.every = max(1, int(round(BUMPER_PERIOD / dt)))
        self.reach_time = self.every * dt
        self._dirs = _bumper_fan()
        self._gid = np.zeros(len(self._dirs), np.int32)
        self._dist = np.zeros(len(self._dirs))
        spec = robot.desc.ultrasonic
        self._center = spec.center if spec is not None else (0.0, 0.0)
        self._shell = spec.radius if spec is not None else robot.desc.base_radius

    def after_step(self, physics: Physics) -> None:
        c = self.robot.ctrl
        if abs(c.v) < 1e-6:
            return
        cx, cy = self._center
        cos, sin = math.cos(c.yaw), math.sin(c.yaw)
        heading = c.yaw if c.v > 0 else c.yaw + math.pi
        ch, sh = math.cos(heading), math.sin(heading)
        vec = (self._dirs @ np.array([[ch, sh, 0.0], [-sh, ch, 0.0], [0.0, 0.0, 1.0]])).reshape(-1)
        origin = np.array([c.x + cos * cx - sin * cy, c.y + sin * cx + cos * cy, 0.0])
        reach = self._shell + abs(c.v) * self.reach_time + 0.01
        for h in BUMPER_HEIGHTS:
            origin[2] = h
            mujoco.mj_multiRay(
                physics.model,
                physics.data,
                origin,
                vec,
                SENSED_GROUPS,
                1,
                self.robot.body_id,
                self._gid,
                self._dist,
                None,
                len(self._gid),
                reach,
            )
            near = (self._dist >= 0) & (self._dist < reach)
            if near.any():
                c.stop()
                what = hit_owner(physics.model, int(self._gid[int(np.argmax(near))]))
                detail = f"stopped before {what} ahead at ({c.x:.2f}, {c.y:.2f})"
                self.robot.note(
                    Note(
                        EventKind.COLLISION,
                        "bumper",
                        "warning",
                        {"t": physics.time, "detail": detail, "what": what},
                        counter="collisions",
                    )
                )
                break


def hit_owner(model: mujoco.MjModel, geom: int) -> str:
    """What a ray hit, for the event: the robot that holds the geom (its id: the prefix of its bodies' names,
    ``"{id}/"``), or the scene's body name; a collision that names a base tells two bases that met from a shelf."""
    if geom < 0:
        return "the scene"
    body = int(model.geom_bodyid[geom])
    name = model.body(body).name if body else model.geom(geom).name  # the world's own geoms: the wall's name
    return name.split("/", 1)[0] if "/" in name else (name or "the scene")
