"""A world's sensor reads on demand: a robot's LIDAR or ultrasonic ranges, an arm's flange pose or velocity.

The peer publishes these through each robot's streams (:mod:`sim_peer.serving.streams`); this is the direct read
for code that holds the world itself (benchmarks, tests, tools). Each read brings the world's positions up
to date first (:mod:`sim_peer.physics.positions`) and names what is missing when a robot lacks the part.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np

from sim_peer.physics.positions import Positions


class Readings:
    """Reads of one world's robots by id; ``robot`` looks a robot up (KeyError naming the world's robots)."""

    def __init__(self, robot: Callable[[str], Any], data: mujoco.MjData, positions: Positions) -> None:
        self._robot = robot
        self._data = data
        self._positions = positions

    def _part(self, robot_id: str, part: str, missing: str) -> Any:
        found = getattr(self._robot(robot_id), part, None)
        if found is None:
            raise KeyError(f"robot {robot_id!r} {missing}")
        self._positions.sync()
        return found

    def scan(self, robot_id: str) -> np.ndarray:
        """The robot's LIDAR ranges now (m)."""
        return self._part(robot_id, "lidar", "has no LIDAR").read(self._data)

    def sonar(self, robot_id: str) -> np.ndarray:
        """The robot's ultrasonic ranges now (m)."""
        return self._part(robot_id, "sonar", "has no ultrasonic ring").read(self._data)

    def flange(self, robot_id: str) -> tuple[np.ndarray, np.ndarray]:
        """Flange position and quaternion (w, x, y, z) of an arm, world frame."""
        return self._part(robot_id, "flange", "is not an arm")(self._data)

    def flange_velocity(self, robot_id: str) -> tuple[np.ndarray, np.ndarray]:
        """Flange linear and angular velocity of an arm, world frame (J(q) dq)."""
        return self._part(robot_id, "flange_velocity", "is not an arm")(self._data)


__all__ = ["Readings"]
