"""Which streams a user peer decodes: every scene object's pose and every map (latched), and a robot's streams
only from its first handle on.

A student of a class decodes her own robots' streams, not the whole world's (32 robots: ~4,600 messages a
second each); what was set before she joined (objects, maps, a planned path) comes at once.
"""

from __future__ import annotations

from typing import Any

from fabric import keys
from fabric.session import Fabric
from user_peer.latest import Latest

__all__ = ["FOLLOWED_STREAMS", "Following"]

FOLLOWED_STREAMS = ("joints", "pose", "scan", "path", "ik")
"""The streams a robot handle keeps the latest of (:meth:`World.robot`)."""


class Following:
    """Subscriptions that feed ``latest``: objects and maps at once, robots when :meth:`robot` is asked."""

    def __init__(self, fabric: Fabric, world: str, latest: Latest) -> None:
        self.fabric = fabric
        self.world = world
        self.latest = latest
        self._robots: set[str] = set()
        # every writer's pose of an object is kept under the object's reader key (object/{id}/pose/by/*)
        fabric.subscribe(keys.object_pose_all(world), self._on_object_pose, history=True)
        fabric.subscribe(f"{keys.world_root(world)}/map/*", latest.put, history=True)

    @property
    def robots(self) -> frozenset[str]:
        """The robots whose streams are followed so far."""
        return frozenset(self._robots)

    def robot(self, robot_id: str) -> bool:
        """Keep the latest of ``robot_id``'s streams from now on; True the first time it is asked for the robot
        (a :class:`~user_peer.robot.Robot` handle asks, once per robot) (ik: a compute peer's streamed IK,
        Test A); paths are latched (a path planned before the handle comes at once)."""
        if robot_id in self._robots:
            return False
        self._robots.add(robot_id)
        for stream in FOLLOWED_STREAMS:
            self.fabric.subscribe(keys.robot_stream(self.world, robot_id, stream), self.latest.put, history=stream == "path")
        return True

    def _on_object_pose(self, key: str, msg: Any) -> None:
        self.latest.put(keys.object_pose_all(self.world, keys.parse(key).subject), msg)
