"""The simulation peer: MuJoCo worlds with robots, their controllers and sensors, and the peer that serves them.

The core (:mod:`sim_peer.world`, :mod:`sim_peer.controllers`, :mod:`sim_peer.follower`,
:mod:`sim_peer.sensors`) has no Zenoh import; :mod:`sim_peer.peer` composes it with
the fabric: streams, commands through a :class:`fabric.gate.CommandGate`, the
world service.
"""

from sim_peer.controllers import ArmController, BaseController, Clamp, CommandRejected
from sim_peer.follower import PurePursuit
from sim_peer.sensors import Lidar, Ultrasonic
from sim_peer.simrobot import ArmRobot, MobileRobot, SimRobot
from sim_peer.world import World, WorldError, parse_robot_spec

__all__ = [
    "ArmController",
    "ArmRobot",
    "BaseController",
    "Clamp",
    "CommandRejected",
    "Lidar",
    "MobileRobot",
    "PurePursuit",
    "SimRobot",
    "Ultrasonic",
    "World",
    "WorldError",
    "parse_robot_spec",
]
