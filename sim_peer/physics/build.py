"""Building a world's MuJoCo model: which robots, with which descriptions, attached where.

:func:`resolve` turns a scene and ``TYPE:ID`` specs into the placed robots and their descriptions (ids
checked, the command line's sensor options applied); :func:`compile_model` attaches each robot's MJCF under
the prefix ``"{id}/"`` at the frame its robot class asks for and compiles the whole; :func:`scene_objects`
finds each scene object's mocap body.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

import mujoco

import robots as robots_pkg
from fabric.keys import validate_id
from robots import RobotDescription, SceneDescription, SceneRobot
from sim_peer.physics.errors import WorldError
from sim_peer.physics.mirrors import add_slots
from sim_peer.physics.placement import parse_robot_spec
from sim_peer.physics.registry import robot_class


@dataclass(frozen=True, slots=True)
class SensorOptions:
    """Sensor settings that override every robot's description (the sim's command line)."""

    noise_std: float | None = None
    lidar_rays: int | None = None
    lidar_fov_deg: float | None = None


def load_scene(scene: SceneDescription | str) -> SceneDescription:
    try:
        return scene if isinstance(scene, SceneDescription) else robots_pkg.scene(scene)
    except robots_pkg.DescriptionError as exc:
        raise WorldError(str(exc)) from None


def resolve(
    scene: SceneDescription, robots: Iterable[SceneRobot | str], *, scene_robots: bool, options: SensorOptions
) -> tuple[list[SceneRobot], dict[str, RobotDescription]]:
    """The robots of the world (the scene's, then ``robots``) and each one's description, by id."""
    placed: list[SceneRobot] = list(scene.robots) if scene_robots else []
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
    clash = sorted(set(ids) & {o.id for o in scene.objects})
    if clash:  # one ownership namespace: robots and scene objects
        raise WorldError(f"robot id(s) {', '.join(clash)} are also scene objects of {scene.name}")
    descriptions: dict[str, RobotDescription] = {}
    for r in placed:
        try:
            desc = robots_pkg.load(r.type)
        except robots_pkg.DescriptionError as exc:
            raise WorldError(str(exc)) from None
        descriptions[r.id] = with_options(desc, options)
    return placed, descriptions


def with_options(desc: RobotDescription, options: SensorOptions) -> RobotDescription:
    """``desc`` with the sensor options applied (checked: rays 1..4096, field of view (0, 360] deg)."""
    noise, rays, fov = options.noise_std, options.lidar_rays, options.lidar_fov_deg
    if desc.lidar is not None and (rays is not None or fov is not None or noise is not None):
        lid = desc.lidar
        if rays is not None:
            if not 1 <= rays <= 4096:
                raise WorldError(f"lidar rays must be in 1..4096, got {rays}")
            lid = replace(lid, rays=int(rays))
        if fov is not None:
            if not 0 < fov <= 360:
                raise WorldError(f"lidar field of view must be in (0, 360] deg, got {fov}")
            lid = replace(lid, fov=math.radians(fov))
        if noise is not None:
            lid = replace(lid, noise_std=float(noise))
        desc = replace(desc, lidar=lid)
    if desc.ultrasonic is not None and noise is not None:
        desc = replace(desc, ultrasonic=replace(desc.ultrasonic, noise_std=float(noise)))
    return desc


def compile_model(
    scene: SceneDescription,
    placed: Sequence[SceneRobot],
    descriptions: Mapping[str, RobotDescription],
    *,
    mirrors: int = 0,
) -> mujoco.MjModel:
    """The scene's MJCF with every robot's MJCF attached under ``"{id}/"``, and ``mirrors`` parked mirror slots
    for robots other sims simulate (:mod:`sim_peer.physics.mirrors`), compiled."""
    spec = mujoco.MjSpec.from_file(str(scene.mjcf_path))
    add_slots(spec, mirrors)
    for r in placed:
        desc = descriptions[r.id]
        child = mujoco.MjSpec.from_file(str(desc.mjcf_path))
        pos, quat = robot_class(desc).frame(r.pose)
        frame = spec.worldbody.add_frame(pos=pos, quat=quat)
        root = child.body(desc.root_body)
        if root is None:
            raise WorldError(f"robot type {desc.name}: root body {desc.root_body!r} is not in {desc.mjcf_path}")
        frame.attach_body(root, f"{r.id}/", "")
    try:
        return spec.compile()
    except Exception as exc:  # MuJoCo compile errors are plain ValueErrors with the XML detail
        raise WorldError(f"scene {scene.name}: {exc}") from None


def scene_objects(model: mujoco.MjModel, scene: SceneDescription) -> dict[str, int]:
    """Each scene object's mocap index; :class:`WorldError` for an object without a mocap body."""
    objects: dict[str, int] = {}
    for o in scene.objects:
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, o.body)
        mocap = int(model.body_mocapid[bid]) if bid >= 0 else -1
        if mocap < 0:
            raise WorldError(f"scene {scene.name}: object {o.id!r} needs a mocap body named {o.body!r}")
        objects[o.id] = mocap
    return objects


__all__ = ["SensorOptions", "compile_model", "load_scene", "resolve", "scene_objects", "with_options"]
