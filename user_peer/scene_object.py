"""Scene objects as a user sees them: things anyone may move (the IK target sphere, the goal pointer).

Each user writes an object's pose on its own key (``object/{id}/pose/by/{user}``); everyone reads all of
them, and the sim applies the last one. There is no ownership, so no lease and no refusal but a bad frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from fabric import keys
from fabric.interfaces import Pose, quaternion_from_yaw
from user_peer.streams import Subscription

if TYPE_CHECKING:
    from user_peer.world import World

__all__ = ["SceneObject"]


class SceneObject:
    """A scene object (policy ``scene``: anyone writes, last writer wins)."""

    def __init__(self, world: "World", object_id: str) -> None:
        self.world = world
        self.id = object_id
        self.key = keys.object_pose(world.name, object_id, world.user)  # where this user writes it
        self.any_key = keys.object_pose_all(world.name, object_id)  # where anyone's pose of it is read

    def __repr__(self) -> str:
        return f"<SceneObject {self.id!r}>"

    @property
    def pose(self) -> Pose | None:
        return self.world.latest.get(self.any_key)

    def set_pose(
        self, position: Sequence[float], quaternion: Sequence[float] = (1.0, 0.0, 0.0, 0.0), *, yaw: float | None = None
    ) -> Pose:
        """Move the object to ``position`` (m, world frame); ``yaw`` (rad) overrides ``quaternion``."""
        if yaw is not None:
            quaternion = quaternion_from_yaw(yaw)
        pose = Pose(
            np.asarray(position, dtype=float),
            np.asarray(quaternion, dtype=float),
            header=self.world.fabric.header(self.key),
        )
        self.world.fabric.publish(self.key, pose)
        self.world.latest.put(self.any_key, pose)
        return pose

    def on(self, callback: Callable[[str, Any], None]) -> Subscription:
        return self.world.on(self.any_key, callback)
