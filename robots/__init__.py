"""Robot descriptions and scenes, as data.

``robots.load("meca500")`` returns a :class:`RobotDescription` (joint names,
limits in rad, speeds in rad/s, URDF and MJCF paths, flange site/frame, base
and sensor specs for mobile robots); ``robots.scene("combined")`` returns a
:class:`SceneDescription` (MJCF path, robots with types and ids, scene objects
such as the ``target`` sphere and the ``goal`` pointer as mocap bodies).
The Meca500's files are generated from ``robots/meca500/geometry.py``.
"""

from robots.description import (
    BaseSpec,
    DescriptionError,
    LidarSpec,
    RobotDescription,
    SceneDescription,
    SceneObject,
    SceneRobot,
    UltrasonicSpec,
    available_robots,
    available_scenes,
    installed,
    load,
    scene,
    search_path,
)

__all__ = [
    "BaseSpec",
    "DescriptionError",
    "LidarSpec",
    "RobotDescription",
    "SceneDescription",
    "SceneObject",
    "SceneRobot",
    "UltrasonicSpec",
    "available_robots",
    "available_scenes",
    "installed",
    "load",
    "scene",
    "search_path",
]
