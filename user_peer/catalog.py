"""What kind of robot is behind an id, and where it stands: world description, scenes, joint names.

A live viewer asks the sim peer's world description (``rf/{world}/srv/world``)
so it needs no local copy of the world. An export from a recording has no one
to ask: it looks the id up in the scene descriptions of ``robots/`` (type and
placement), and failing that matches a JointState's joint names against the
robot types. Either way the geometry comes from the same robot descriptions
(URDF) the sim and the compute peer use.
"""

from __future__ import annotations

import logging
import threading

import numpy as np

import robots
from fabric.interfaces import WorldInfo
from fabric.interfaces.geometry import quaternion_from_yaw
from robots.kinds import facts
from user_peer.arm_geometry import ArmGeometry, Placement
from user_peer.geometry import quat_xyzw
from user_peer.rerun_log import RobotDrawing

log = logging.getLogger("robofabric.viewer")

__all__ = ["RobotCatalog", "placement_xyz_yaw"]


def placement_xyz_yaw(x: float, y: float, z: float, yaw: float) -> Placement:
    """A base standing at (x, y, z) turned by ``yaw`` about z (Placement keeps quaternions as x, y, z, w)."""
    return Placement(np.array([x, y, z], dtype=float), np.array(quat_xyzw(quaternion_from_yaw(yaw))))


class RobotCatalog:
    """Builds :class:`RobotDrawing` for robot ids; caches descriptions and arm geometries per type.

    Safe from several threads (the ROS 2 bridge draws from zenoh's callbacks): each cache is filled under one lock
    and seen only whole; a thread that read a half-filled one drew a Meca500 as a mobile base of no size and a
    Reeman without its sonar ring, and kept those drawings (issue 46)."""

    def __init__(self, world_info: WorldInfo | None = None, *, scene: str | None = None) -> None:
        self.world_info: WorldInfo | None = world_info
        self.scene_name = scene
        self._models: dict[str, ArmGeometry | None] = {}
        self._descs: dict[str, robots.RobotDescription] | None = None
        self._scene_robots: list[robots.SceneRobot] | None = None
        self._lock = threading.RLock()  # the caches' loads: one thread loads, the others wait for the whole

    def descriptions(self) -> dict[str, robots.RobotDescription]:
        with self._lock:
            if self._descs is None:
                descs = {}
                for name in robots.available_robots():
                    try:
                        descs[name] = robots.load(name)
                    except robots.DescriptionError as exc:
                        log.warning("skipping robot type %s: %s", name, exc)
                self._descs = descs
            return self._descs

    def scene_robots(self) -> list[robots.SceneRobot]:
        """Robots placed by the named scene, or by every known scene (first placement of an id wins)."""
        with self._lock:
            return self._load_scene_robots()

    def _load_scene_robots(self) -> list[robots.SceneRobot]:
        if self._scene_robots is None:
            names = [self.scene_name] if self.scene_name else robots.available_scenes()
            out: list[robots.SceneRobot] = []
            for name in names:
                try:
                    out.extend(robots.scene(name).robots)
                except robots.DescriptionError as exc:
                    log.warning("skipping scene %s: %s", name, exc)
            self._scene_robots = out
        return self._scene_robots

    def arm_geometry(self, rtype: str) -> ArmGeometry | None:
        with self._lock:
            return self._arm_geometry(rtype)

    def _arm_geometry(self, rtype: str) -> ArmGeometry | None:
        if rtype not in self._models:
            model = None
            d = self.descriptions().get(rtype)
            if d is not None and d.urdf_path is not None:
                try:
                    model = ArmGeometry(d.urdf_path)
                except Exception as exc:
                    log.warning("cannot build a kinematic model of %s from %s: %s", rtype, d.urdf_path, exc)
            self._models[rtype] = model
        return self._models[rtype]

    def _world_entry(self, rid: str) -> tuple[str, Placement | None] | None:
        """(type, base placement) of ``rid`` in the sim's world description, or None (no description, or not in it)."""
        if self.world_info is None:
            return None
        for r in self.world_info.robots:
            if r.id == rid:
                return r.type, placement_xyz_yaw(*(float(v) for v in r.pose))
        return None

    def describes(self, rid: str) -> bool:
        """Whether the sim's world description names ``rid``: a drawing guessed before it came is made again."""
        return self._world_entry(rid) is not None

    def drawing(self, rid: str, hint: dict) -> RobotDrawing:
        """RobotDrawing for ``rid``: world description, then scenes, then joint names."""
        rtype, base = "", None
        found = self._world_entry(rid)
        names = tuple(hint.get("joint_names", ()))
        if found is not None:
            rtype, base = found
        else:
            for sr in self.scene_robots():
                d = self.descriptions().get(sr.type)
                if sr.id == rid and d is not None and (not names or d.joint_names == names):
                    rtype, base = sr.type, placement_xyz_yaw(*sr.pose)
                    break
        if not rtype and names:
            rtype = next((n for n, d in self.descriptions().items() if d.joint_names == names), "")
        d = self.descriptions().get(rtype)
        kind = d.kind if d is not None else ("mobile" if hint.get("mobile") else "")
        info = RobotDrawing(rid, rtype, kind)
        if facts(kind).chain:
            info.arm = self.arm_geometry(rtype)
            info.base = base
        elif d is not None and d.base is not None:
            info.radius = d.base.radius
            info.height = d.base.height or info.height
            info.lidar_offset = self.lidar_offset(d)
            if d.ultrasonic is not None:
                us = d.ultrasonic
                info.sonar = (float(us.center[0]), float(us.center[1]), float(us.height), float(us.radius))
        return info

    def lidar_offset(self, d: robots.RobotDescription) -> tuple[float, float, float]:
        """Where the LIDAR sits on the base (from the robot's MJCF site), so scans are drawn from it."""
        default = (0.0, 0.0, 0.3)
        if d.lidar is None:
            return default
        try:
            import mujoco

            m = mujoco.MjModel.from_xml_path(str(d.mjcf_path))
            sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, d.lidar.site)
            if sid < 0:
                return default
            return tuple(float(v) for v in m.site_pos[sid])  # type: ignore[return-value]
        except Exception as exc:
            log.debug("no lidar offset for %s: %s", d.name, exc)
            return default
