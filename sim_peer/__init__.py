"""The simulation peer: MuJoCo worlds with robots, their controllers and sensors, and the peer that serves them.

The core (:mod:`sim_peer.world` and the modules it composes: :mod:`sim_peer.build`, :mod:`sim_peer.placement`,
:mod:`sim_peer.bumper`; the robot plug-ins :mod:`sim_peer.robot`, :mod:`sim_peer.robot_kinds`,
:mod:`sim_peer.registry`; :mod:`sim_peer.controllers`, :mod:`sim_peer.pure_pursuit`, :mod:`sim_peer.sensors`) has
no Zenoh import; :mod:`sim_peer.peer` composes it with the fabric: streams, commands through a
:class:`fabric.gate.CommandGate`, the world service.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sim_peer.controllers import ArmController, BaseController, Clamp, CommandRejected
    from sim_peer.pure_pursuit import PurePursuit
    from sim_peer.robot import HOOKS, Mount, Note, Physics, SimRobot, Stream
    from sim_peer.sensors import Lidar, Sensor, Ultrasonic
    from sim_peer.robot_kinds import ArmRobot, MobileRobot
    from sim_peer.world import SimWorld, WorldError, parse_robot_spec

__all__ = [
    "ArmController",
    "ArmRobot",
    "BaseController",
    "Clamp",
    "CommandRejected",
    "HOOKS",
    "Lidar",
    "MobileRobot",
    "Mount",
    "Note",
    "Physics",
    "PurePursuit",
    "SimRobot",
    "Sensor",
    "SimWorld",
    "Stream",
    "Ultrasonic",
    "WorldError",
    "parse_robot_spec",
]


def __getattr__(name: str) -> Any:
    """The core loads on first use of one of its names: ``robofabric --help`` imports ``sim_peer.cli``, and with it
    this package, and must not pay for MuJoCo (a quarter of a second) it never uses."""
    if name not in __all__:
        raise AttributeError(f"module 'sim_peer' has no attribute {name!r}")
    from sim_peer import controllers, pure_pursuit, robot, robot_kinds, sensors, world

    for mod in (controllers, pure_pursuit, robot, robot_kinds, sensors, world):
        if hasattr(mod, name):
            return getattr(mod, name)
    raise AttributeError(f"module 'sim_peer' has no attribute {name!r}")
