"""Range sensors by ray casting with ``mujoco.mj_multiRay``.

A LIDAR casts its rays from one site; an ultrasonic ring casts one small fan of
rays per sensor from the base's centre axis and subtracts the ring radius. The
robot's own body is excluded (``bodyexclude``), markers in geom group 3 and
above are invisible to the rays. A ray that hits nothing within range reads
``range_max``; noise, when asked for, is Gaussian from a seeded generator.

MuJoCo 4 signature: ``mj_multiRay(m, d, pnt, vec, geomgroup, flg_static,
bodyexclude, geomid, dist, normal, nray, cutoff)``; ``dist`` is -1 for a miss.

Sensors are plug-ins of the robot that holds them (:mod:`sim_peer.robot`): ``describe(info)`` fills in their
typed part of the robot's description (``RobotInfo.lidar``, ``.sonar``), ``streams()`` what they publish,
``after_step()`` a check run every step.
"""

from __future__ import annotations

import math
from dataclasses import replace

import mujoco
import numpy as np

from fabric.interfaces import LidarInfo, RobotInfo, Scan, SonarInfo
from robots import LidarSpec, UltrasonicSpec
from sim_peer.robot import Build, Physics, Stream

SENSED_GROUPS = np.array([1, 1, 1, 0, 0, 0], dtype=np.uint8)  # environment 0, robots 1, extra 2; markers 3 unseen
SONAR_STREAM = "sonar"


class Sensor:
    """Empty hooks: a sensor overrides the ones it needs. ``every``: its ``after_step`` runs on the steps that
    are multiples of it, while the world is stepping."""

    every = 1

    def describe(self, info: RobotInfo) -> RobotInfo:
        """The robot's description with this sensor's part filled in (a sensor others need not know of: as is)."""
        return info

    def after_step(self, physics: Physics) -> None:
        """A check after every step (the bumper's)."""

    def streams(self) -> tuple[Stream, ...]:
        return ()


class Lidar(Sensor):
    """A planar LIDAR on a site: ``read(data)`` gives ranges (m) for rays from angle_min by angle_increment."""

    def __init__(
        self, model: mujoco.MjModel, spec: LidarSpec, site_id: int, body_id: int, rng: np.random.Generator | None = None
    ) -> None:
        self.model = model
        self.spec = spec
        self.site_id = site_id
        self.body_id = body_id
        self.rng = rng
        angles = spec.angle_min + spec.angle_increment * np.arange(spec.rays)
        self.angles = angles
        self._local = np.column_stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
        self._vec = np.zeros(3 * spec.rays)
        self._geomid = np.zeros(spec.rays, dtype=np.int32)
        self._dist = np.zeros(spec.rays)

    def read(self, data: mujoco.MjData) -> np.ndarray:
        s = self.spec
        rot = data.site_xmat[self.site_id].reshape(3, 3)
        self._vec[:] = (self._local @ rot.T).reshape(-1)
        mujoco.mj_multiRay(
            self.model,
            data,
            data.site_xpos[self.site_id],
            self._vec,
            SENSED_GROUPS,
            1,
            self.body_id,
            self._geomid,
            self._dist,
            None,
            s.rays,
            s.range_max,
        )
        return _finish(self._dist, s.range_min, s.range_max, s.noise_std, self.rng)

    def describe(self, info: RobotInfo) -> RobotInfo:
        li = self.spec
        return replace(
            info,
            lidar=LidarInfo(
                site=li.site,
                rays=li.rays,
                fov=li.fov,
                angle_min=li.angle_min,
                angle_increment=li.angle_increment,
                range_min=li.range_min,
                range_max=li.range_max,
                noise_std=li.noise_std,
                offset=np.array(self.model.site_pos[self.site_id], dtype=np.float64),  # in the robot frame
            ),
        )

    def streams(self) -> tuple[Stream, ...]:
        return (Stream("scan", "scan", self._sample, positions=True),)

    def _sample(self, physics: Physics) -> Build:
        ranges = self.read(physics.data)
        s = self.spec
        return lambda header: Scan.from_ranges(
            ranges, angle_min=s.angle_min, angle_increment=s.angle_increment, range_max=s.range_max, header=header
        )


class Ultrasonic(Sensor):
    """A ring of range sensors around a mobile base: ``read(data)`` gives one range (m) per sensor."""

    BEAM = math.radians(15.0)  # half-width of each sensor's fan of three rays

    def __init__(
        self, model: mujoco.MjModel, spec: UltrasonicSpec, body_id: int, rng: np.random.Generator | None = None
    ) -> None:
        self.model = model
        self.spec = spec
        self.body_id = body_id
        self.rng = rng
        self.center = np.array([spec.center[0], spec.center[1], spec.height])
        a = np.asarray(spec.angles, dtype=np.float64)
        fan = np.concatenate([a - self.BEAM, a, a + self.BEAM])
        self._n = fan.shape[0]
        self._local = np.column_stack([np.cos(fan), np.sin(fan), np.zeros_like(fan)])
        self._vec = np.zeros(3 * self._n)
        self._geomid = np.zeros(self._n, dtype=np.int32)
        self._dist = np.zeros(self._n)

    def read(self, data: mujoco.MjData) -> np.ndarray:
        s = self.spec
        rot = data.xmat[self.body_id].reshape(3, 3)
        origin = data.xpos[self.body_id] + rot @ self.center
        self._vec[:] = (self._local @ rot.T).reshape(-1)
        cutoff = s.range_max + s.radius
        mujoco.mj_multiRay(
            self.model,
            data,
            origin,
            self._vec,
            SENSED_GROUPS,
            1,
            self.body_id,
            self._geomid,
            self._dist,
            None,
            self._n,
            cutoff,
        )
        d = np.where(self._dist >= 0, self._dist - s.radius, -1.0)
        d = d.reshape(3, -1)
        hit = np.where(d >= 0, d, np.inf).min(axis=0)
        hit = np.where(np.isfinite(hit), hit, -1.0)
        return _finish(hit, s.range_min, s.range_max, s.noise_std, self.rng)

    def describe(self, info: RobotInfo) -> RobotInfo:
        us = self.spec
        return replace(
            info,
            sonar=SonarInfo(
                angles=np.array(us.angles, dtype=np.float64),
                radius=us.radius,
                height=us.height,
                range_min=us.range_min,
                range_max=us.range_max,
                noise_std=us.noise_std,
                center=np.array(us.center, dtype=np.float64),
            ),
        )

    def streams(self) -> tuple[Stream, ...]:
        """The ring on its own key (``sonar``), published with the LIDAR's rate group."""
        return (Stream(SONAR_STREAM, "scan", self._sample, positions=True),)

    def _sample(self, physics: Physics) -> Build:
        ranges = self.read(physics.data)
        s = self.spec
        inc = (s.angles[1] - s.angles[0]) if len(s.angles) > 1 else 0.0
        return lambda header: Scan.from_ranges(
            ranges, angle_min=s.angles[0], angle_increment=inc, range_max=s.range_max, header=header
        )


def _finish(
    dist: np.ndarray, range_min: float, range_max: float, noise_std: float, rng: np.random.Generator | None
) -> np.ndarray:
    miss = (dist < 0) | (dist > range_max)
    r = np.where(miss, range_max, dist)
    if noise_std > 0 and rng is not None:
        r = np.where(miss, r, r + rng.normal(0.0, noise_std, r.shape))
    return np.clip(r, range_min, range_max)
