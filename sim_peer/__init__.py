"""The simulation peer: MuJoCo worlds with robots, their controllers and sensors, and the peer that serves them.

At the top, what a robot type imports (:mod:`sim_peer.robot`, :mod:`sim_peer.controllers`, :mod:`sim_peer.sensors`,
:mod:`sim_peer.bumper`) and the CLI; below it four rooms (docs/architecture.md):

- :mod:`sim_peer.physics`: the MuJoCo world (:mod:`sim_peer.physics.world` and what it composes), no zenoh;
- :mod:`sim_peer.serving`: the world served on the fabric (:mod:`sim_peer.serving.peer`: streams, commands through a
  :class:`fabric.gate.CommandGate`, the world service);
- :mod:`sim_peer.replica`: a primary and its standbys, with the election and the other pure decision cores;
- :mod:`sim_peer.shards`: several sims in one world: the shard directory, mirrors fed from the others, moves.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sim_peer.controllers import ArmController, BaseController, Clamp, CommandRejected
    from sim_peer.physics.pure_pursuit import PurePursuit
    from sim_peer.robot import HOOKS, Mount, Note, Physics, SimRobot, Stream
    from sim_peer.sensors import Lidar, Sensor, Ultrasonic
    from sim_peer.physics.robot_kinds import ArmRobot, MobileRobot
    from sim_peer.physics.world import SimWorld, WorldError, parse_robot_spec

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
    from sim_peer import controllers, robot, sensors
    from sim_peer.physics import pure_pursuit, robot_kinds, world

    for mod in (controllers, pure_pursuit, robot, robot_kinds, sensors, world):
        if hasattr(mod, name):
            return getattr(mod, name)
    raise AttributeError(f"module 'sim_peer' has no attribute {name!r}")
