"""What the viewer knows about one robot (:class:`RobotDrawing`), and the colours robots get in turn."""

from __future__ import annotations

from dataclasses import dataclass

from user_peer.arm_geometry import ArmGeometry, Placement

__all__ = ["ROBOT_COLORS", "RobotDrawing"]

ROBOT_COLORS = [(230, 120, 40), (40, 140, 230), (90, 200, 90), (200, 80, 200), (230, 200, 40)]


@dataclass
class RobotDrawing:
    """What the viewer knows about one robot: its kind and how to draw it.

    Built on the user's side from the robot descriptions (:class:`user_peer.catalog.RobotCatalog`); not the sim's
    ``RobotInfo`` message, which describes a robot of the world over the wire.
    """

    id: str
    type: str = ""
    kind: str = ""  # "arm" or "mobile"; "" until known
    arm: ArmGeometry | None = None
    base: Placement | None = None  # an arm's base in the world (fixed)
    radius: float = 0.25  # mobile footprint radius
    height: float = 0.3
    lidar_offset: tuple[float, float, float] = (0.0, 0.0, 0.3)
    sonar: tuple[float, float, float, float] | None = None  # ring centre x, y, height, radius (robot frame)
    color: tuple[int, int, int] = (230, 120, 40)
