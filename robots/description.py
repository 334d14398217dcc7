"""Robot and scene descriptions: what a robot or a scene *is*, read from small TOML manifests.

A robot is a folder holding ``robot.toml`` plus its MJCF (and, for arms, a
URDF); a scene is a ``NAME.toml`` next to its MJCF. Both are data: a user adds
a robot or a scene by dropping files in a folder listed in
``ROBOFABRIC_ROBOTS_PATH`` (or passing a path). A robot type the sim's built-in
arm and mobile base do not cover names its own simulation hooks (``hooks``,
resolved by ``sim_peer.physics.registry``; docs/robots.md); this package only reads the name.
"""

from __future__ import annotations

import functools
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from robots.kinds import NAMES, robot_kind

HERE = Path(__file__).resolve().parent
ENV_PATH = "ROBOFABRIC_ROBOTS_PATH"
KINDS = NAMES
"""The kinds a ``[robot] kind`` may name: the rows of :data:`robots.kinds.KINDS`."""


class DescriptionError(ValueError):
    """A robot or scene manifest is missing, malformed or inconsistent; the text says which and why."""


@dataclass(frozen=True, slots=True)
class BaseSpec:
    """A differential-drive base. The robot frame's origin is the midpoint of the wheel axle (its turn point)."""

    radius: float
    wheel_separation: float
    wheel_radius: float
    max_speed: float  # m/s
    max_omega: float  # rad/s
    max_accel: float  # m/s^2
    max_alpha: float  # rad/s^2
    height: float = 0.0
    reverse: bool = False  # it may drive backwards along a path: plans for it may reverse (docs/navigation.md)


@dataclass(frozen=True, slots=True)
class LidarSpec:
    """A planar LIDAR: ``rays`` rays evenly over ``fov`` (rad) centred on the site's x axis."""

    site: str
    rays: int
    fov: float
    range_min: float
    range_max: float
    noise_std: float = 0.0

    @property
    def angle_min(self) -> float:
        return -self.fov / 2

    @property
    def angle_increment(self) -> float:
        return self.fov / (self.rays - 1) if self.rays > 1 else 0.0


@dataclass(frozen=True, slots=True)
class UltrasonicSpec:
    """A ring of range sensors on the base: one ray each at ``angles`` (rad), from ``radius`` at ``height``."""

    angles: tuple[float, ...]
    radius: float
    height: float
    range_min: float
    range_max: float
    noise_std: float = 0.0
    center: tuple[float, float] = (0.0, 0.0)  # ring centre in the robot frame (x, y)


@dataclass(frozen=True, slots=True)
class RobotDescription:
    """Everything about one robot type that peers need without a local simulator."""

    name: str
    kind: str
    directory: Path
    mjcf_path: Path
    root_body: str
    joint_names: tuple[str, ...]
    lower: tuple[float, ...]  # rad
    upper: tuple[float, ...]  # rad
    max_speed: tuple[float, ...]  # rad/s
    urdf_path: Path | None = None
    flange_site: str = ""
    flange_frame: str = ""
    base_radius: float = 0.0
    description: str = ""
    base: BaseSpec | None = None
    lidar: LidarSpec | None = None
    ultrasonic: UltrasonicSpec | None = None
    base_joints: tuple[str, ...] = ()  # mobile: planar x, y, yaw joints of the root body
    hooks: str = (
        ""  # the sim's plug-in for this type: "package.module:Class" or "file.py:Class" beside robot.toml; "" = by kind
    )

    @property
    def dof(self) -> int:
        return len(self.joint_names)


@dataclass(frozen=True, slots=True)
class SceneRobot:
    """A robot placed in a scene: its type, its id in the world and its pose (x, y, z, yaw)."""

    type: str
    id: str
    pose: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class SceneObject:
    """A scene object any user may move (ownership policy ``scene``): a mocap body of the scene MJCF."""

    id: str
    body: str
    kind: str = ""
    policy: str = "scene"


@dataclass(frozen=True, slots=True)
class SceneDescription:
    name: str
    mjcf_path: Path
    robots: tuple[SceneRobot, ...]
    objects: tuple[SceneObject, ...]
    timestep: float = 0.002
    description: str = ""
    extra: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- search path


ENTRY_POINTS = "robofabric.robots"
"""Entry-point group of packages that install robots: each entry point's value names a package (``"mypkg.robots"``)
whose folder holds robot folders (``NAME/robot.toml``), as ``robots/`` does."""

_TYPE_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_-]{0,63}$")


@functools.cache
def plugin_dirs() -> tuple[Path, ...]:
    """The folders of the packages installed under :data:`ENTRY_POINTS` (read once per process: what the
    operator installed before starting it). A package is found, not run (``importlib.util.find_spec``; a dotted
    name imports its parent packages)."""
    import importlib.metadata
    import importlib.util

    out: list[Path] = []
    for ep in sorted(importlib.metadata.entry_points(group=ENTRY_POINTS), key=lambda e: e.name):
        try:
            spec = importlib.util.find_spec(ep.value.partition(":")[0])
        except (ImportError, ValueError):
            continue  # a broken plug-in hides its robots, not everyone's
        if spec is not None:
            out += [Path(p) for p in (spec.submodule_search_locations or ())]
    return tuple(out)


def search_path() -> list[Path]:
    """Folders searched for robots (``*/robot.toml``) and scenes (``scenes/*.toml`` or ``*.toml``): env first, then
    the packages of :data:`ENTRY_POINTS`, then this package."""
    dirs = [Path(p) for p in os.environ.get(ENV_PATH, "").split(os.pathsep) if p]
    return [*dirs, *plugin_dirs(), HERE]


def available_robots() -> list[str]:
    names = set()
    for d in search_path():
        for manifest in d.glob("*/robot.toml"):
            names.add(manifest.parent.name)
    return sorted(names)


def available_scenes() -> list[str]:
    names = set()
    for d in search_path():
        for sub in (d / "scenes", d):
            for manifest in sub.glob("*.toml"):
                try:
                    if "scene" in tomllib.loads(manifest.read_text()):
                        names.add(manifest.stem)
                except (OSError, tomllib.TOMLDecodeError):
                    continue
    return sorted(names)


def _read(path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text())
    except OSError as exc:
        raise DescriptionError(f"cannot read {path}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise DescriptionError(f"{path} is not valid TOML: {exc}") from None


def _floats(d: dict, key: str, where: str, n: int | None = None) -> tuple[float, ...]:
    v = d.get(key)
    if not isinstance(v, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        raise DescriptionError(f"{where}: {key} must be a list of numbers")
    if n is not None and len(v) != n:
        raise DescriptionError(f"{where}: {key} has {len(v)} values, expected {n}")
    if not all(math.isfinite(x) for x in v):
        raise DescriptionError(f"{where}: {key} must be finite")
    return tuple(float(x) for x in v)


def _num(d: dict, key: str, where: str, default: float | None = None) -> float:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise DescriptionError(f"{where}: {key} must be a finite number, got {v!r}")
    return float(v)


def _flag(d: dict, key: str, where: str) -> bool:
    v = d.get(key, False)
    if not isinstance(v, bool):
        raise DescriptionError(f"{where}: {key} must be true or false, got {v!r}")
    return v


def _find_robot(name: str) -> Path:
    p = Path(name)
    if p.suffix == ".toml" and p.is_file():
        return p
    if p.is_dir() and (p / "robot.toml").is_file():
        return p / "robot.toml"
    for d in search_path():
        cand = d / name / "robot.toml"
        if cand.is_file():
            return cand
    raise DescriptionError(f"unknown robot type {name!r}; known: {', '.join(available_robots()) or 'none'}")


def load(name: str) -> RobotDescription:
    """The description of robot type ``name`` (a folder on the search path, or a path to robot.toml): what the
    operator names on a sim's command line or in a scene file. A type named over the network: :func:`installed`."""
    return _load(_find_robot(name))


def installed(name: str) -> RobotDescription:
    """The description of robot type ``name`` as installed on this machine: a NAME (letters, digits, ``-``,
    ``_``) looked up in the folders of :func:`search_path` (the operator's ``ROBOFABRIC_ROBOTS_PATH``, the
    :data:`ENTRY_POINTS` packages, this package), never a path nor the working directory. What another peer
    names (a robot moved in, another sim's arm to mirror) is read from there, so its hooks are the operator's."""
    if not isinstance(name, str) or not _TYPE_NAME.match(name):
        raise DescriptionError(
            f"robot type {str(name)[:80]!r} is not a type name (1-64 letters, digits, '-', '_'): a type "
            f"named by another peer is looked up among the installed robots, never read from a path"
        )
    for d in search_path():
        cand = d / name / "robot.toml"
        if cand.is_file():
            return _load(cand)
    raise DescriptionError(
        f"robot type {name!r} is not installed here; installed: {', '.join(available_robots()) or 'none'}"
    )


def _load(path: Path) -> RobotDescription:
    data = _read(path)
    where = str(path)
    r = data.get("robot")
    if not isinstance(r, dict):
        raise DescriptionError(f"{where}: missing [robot] table")
    kind = r.get("kind")
    if kind not in KINDS:
        raise DescriptionError(f"{where}: kind must be one of {', '.join(KINDS)}, got {kind!r}")
    d = path.parent
    mjcf = d / str(r.get("mjcf", ""))
    if not mjcf.is_file():
        raise DescriptionError(f"{where}: mjcf file {mjcf} does not exist")
    urdf = d / r["urdf"] if r.get("urdf") else None
    if urdf is not None and not urdf.is_file():
        raise DescriptionError(f"{where}: urdf file {urdf} does not exist")
    joints = r.get("joints", [])
    if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
        raise DescriptionError(f"{where}: joints must be a list of names")
    n = len(joints)
    lower = _floats(r, "lower", where, n)
    upper = _floats(r, "upper", where, n)
    speed = _floats(r, "max_speed", where, n)
    if any(lo > hi for lo, hi in zip(lower, upper)):
        raise DescriptionError(f"{where}: a lower limit is above its upper limit")
    if any(s <= 0 for s in speed):
        raise DescriptionError(f"{where}: max_speed values must be positive")
    base = lidar = sonar = None
    mobile = robot_kind(kind).base
    if mobile:
        base, lidar, sonar = _base(data, where), _lidar(data, where), _sonar(data, where)
    base_joints = tuple(r.get("base_joints", ()))
    if mobile and len(base_joints) != 3:
        raise DescriptionError(f"{where}: a mobile robot needs base_joints = [x, y, yaw] (slide, slide, hinge)")
    return RobotDescription(
        name=str(r.get("name", d.name)),
        kind=kind,
        directory=d,
        mjcf_path=mjcf,
        root_body=str(r.get("root_body", "")),
        joint_names=tuple(joints),
        lower=lower,
        upper=upper,
        max_speed=speed,
        urdf_path=urdf,
        flange_site=str(r.get("flange_site", "")),
        flange_frame=str(r.get("flange_frame", "")),
        base_radius=_num(r, "base_radius", where, base.radius if base else 0.0),
        description=str(r.get("description", "")),
        base=base,
        lidar=lidar,
        ultrasonic=sonar,
        base_joints=base_joints,
        hooks=_hooks_ref(r, where),
    )


def _base(data: dict, where: str) -> BaseSpec:
    """A mobile robot's ``[base]`` table: its size and its limits, all positive."""
    b = data.get("base")
    if not isinstance(b, dict):
        raise DescriptionError(f"{where}: a mobile robot needs a [base] table")
    w = f"{where} [base]"
    base = BaseSpec(
        radius=_num(b, "radius", w),
        wheel_separation=_num(b, "wheel_separation", w),
        wheel_radius=_num(b, "wheel_radius", w),
        max_speed=_num(b, "max_speed", w),
        max_omega=_num(b, "max_omega", w),
        max_accel=_num(b, "max_accel", w),
        max_alpha=_num(b, "max_alpha", w),
        height=_num(b, "height", w, 0.0),
        reverse=_flag(b, "reverse", w),
    )
    if (
        min(
            base.radius,
            base.wheel_separation,
            base.wheel_radius,
            base.max_speed,
            base.max_omega,
            base.max_accel,
            base.max_alpha,
        )
        <= 0
    ):
        raise DescriptionError(f"{w}: sizes and limits must be positive")
    return base


def _lidar(data: dict, where: str) -> LidarSpec | None:
    """A mobile robot's ``[lidar]`` table, if it has one."""
    if not isinstance(data.get("lidar"), dict):
        return None
    li = data["lidar"]
    w = f"{where} [lidar]"
    rays = li.get("rays")
    if not isinstance(rays, int) or not 1 <= rays <= 4096:
        raise DescriptionError(f"{w}: rays must be an integer in 1..4096")
    return LidarSpec(
        site=str(li.get("site", "lidar")),
        rays=rays,
        fov=math.radians(_num(li, "fov_deg", w)),
        range_min=_num(li, "range_min", w, 0.0),
        range_max=_num(li, "range_max", w),
        noise_std=_num(li, "noise_std", w, 0.0),
    )


def _sonar(data: dict, where: str) -> UltrasonicSpec | None:
    """A mobile robot's ``[ultrasonic]`` ring, if it has one."""
    if not isinstance(data.get("ultrasonic"), dict):
        return None
    us = data["ultrasonic"]
    w = f"{where} [ultrasonic]"
    return UltrasonicSpec(
        angles=tuple(math.radians(a) for a in _floats(us, "angles_deg", w)),
        radius=_num(us, "radius", w),
        height=_num(us, "height", w),
        range_min=_num(us, "range_min", w, 0.0),
        range_max=_num(us, "range_max", w),
        noise_std=_num(us, "noise_std", w, 0.0),
        center=_floats(us, "center", w, 2) if "center" in us else (0.0, 0.0),  # type: ignore[arg-type]
    )


def _hooks_ref(r: dict, where: str) -> str:
    """``[robot] hooks``: where the sim finds this type's plug-in (resolved by sim_peer.physics.registry, not here)."""
    ref = r.get("hooks", "")
    if not isinstance(ref, str) or (ref and ref.count(":") != 1):
        raise DescriptionError(f'{where}: hooks must be "package.module:Class" or "file.py:Class", got {ref!r}')
    return ref


def _find_scene(name: str) -> Path:
    p = Path(name)
    if p.suffix == ".toml" and p.is_file():
        return p
    for d in search_path():
        for cand in (d / "scenes" / f"{name}.toml", d / f"{name}.toml"):
            if cand.is_file():
                return cand
    raise DescriptionError(f"unknown scene {name!r}; known: {', '.join(available_scenes()) or 'none'}")


def scene(name: str) -> SceneDescription:
    """The description of scene ``name`` (a ``NAME.toml`` on the search path, or a path to one)."""
    path = _find_scene(name)
    data = _read(path)
    where = str(path)
    s = data.get("scene")
    if not isinstance(s, dict):
        raise DescriptionError(f"{where}: missing [scene] table")
    mjcf = path.parent / str(s.get("mjcf", ""))
    if not mjcf.is_file():
        raise DescriptionError(f"{where}: mjcf file {mjcf} does not exist")
    robots_ = []
    for i, r in enumerate(data.get("robot", [])):
        if not isinstance(r, dict) or not isinstance(r.get("type"), str) or not isinstance(r.get("id"), str):
            raise DescriptionError(f"{where}: robot #{i} needs a type and an id")
        pose = _floats(r, "pose", f"{where} robot {r['id']}", 4) if "pose" in r else (0.0, 0.0, 0.0, 0.0)
        robots_.append(SceneRobot(r["type"], r["id"], pose))  # type: ignore[arg-type]
    ids = [r.id for r in robots_]
    if len(set(ids)) != len(ids):
        raise DescriptionError(f"{where}: robot ids must be unique, got {ids}")
    objects = []
    for i, o in enumerate(data.get("object", [])):
        if not isinstance(o, dict) or not isinstance(o.get("id"), str):
            raise DescriptionError(f"{where}: object #{i} needs an id")
        objects.append(
            SceneObject(o["id"], str(o.get("body", o["id"])), str(o.get("kind", "")), str(o.get("policy", "scene")))
        )
    return SceneDescription(
        name=str(s.get("name", path.stem)),
        mjcf_path=mjcf,
        robots=tuple(robots_),
        objects=tuple(objects),
        timestep=_num(s, "timestep", where, 0.002),
        description=str(s.get("description", "")),
        extra={k: v for k, v in data.items() if k not in ("scene", "robot", "object")},
    )
