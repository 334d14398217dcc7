"""Which streams a user peer decodes: every scene object's pose and every map (latched), and a robot's streams
only from its first handle on, until it is unfollowed.

A student of a class decodes her own robots' streams, not the whole world's (32 robots: ~4,600 messages a
second each); what was set before she joined (objects, maps, a planned path) comes at once. A console page
follows only the robots it shows in full, and lets go of one when the student selects another
(:meth:`Following.unfollow`): each followed robot is a pose at 50 Hz and a scan at 20 Hz, decoded.
"""

from __future__ import annotations

import threading
from typing import Any, Callable, Iterable

from fabric import keys, streams
from fabric.session import Fabric
from user_peer.latest import Latest

__all__ = ["FOLLOWED_STREAMS", "Following"]

FOLLOWED_STREAMS = tuple(s.name for s in streams.STREAMS if s.followed)
"""The streams a robot handle keeps the latest of (:meth:`World.robot`; :attr:`fabric.streams.RobotStream.followed`)."""


class Following:
    """Subscriptions that feed ``latest``: objects and maps at once, robots when :meth:`robot` is asked."""

    def __init__(
        self, fabric: Fabric, world: str, latest: Latest, streams: Callable[[str], Iterable[str]] | None = None
    ) -> None:
        self.fabric = fabric
        self.world = world
        self.latest = latest
        # which of FOLLOWED_STREAMS a followed robot's handle keeps, by robot id (all of them unless told)
        self._streams = streams
        self._subs: dict[str, list[Any]] = {}  # a followed robot's subscriptions, one per stream
        self._lock = threading.Lock()  # handles are made on callers' threads (a console's pages: its pool's)
        # every writer's pose of an object is kept under the object's reader key (object/{id}/pose/by/*)
        fabric.subscribe(keys.object_pose_all(world), self._on_object_pose, history=True)
        fabric.subscribe(f"{keys.world_root(world)}/map/*", latest.put, history=True)

    @property
    def robots(self) -> frozenset[str]:
        """The robots whose streams are followed now."""
        with self._lock:
            return frozenset(self._subs)

    def robot(self, robot_id: str) -> bool:
        """Keep the latest of ``robot_id``'s streams from now on; True when it was not followed (a
        :class:`~user_peer.robot.Robot` handle asks when it is made, once per robot) (ik: a compute peer's streamed IK,
        Test A); paths are latched (a path planned before the handle comes at once)."""
        with self._lock:
            if robot_id in self._subs:
                return False
            self._subs[robot_id] = [
                self.fabric.subscribe(
                    keys.robot_stream(self.world, robot_id, stream),
                    self.latest.put,
                    history=stream in keys.LATCHED_STREAMS,
                )
                for stream in (FOLLOWED_STREAMS if self._streams is None else self._streams(robot_id))
            ]
        return True

    def unfollow(self, robot_id: str) -> bool:
        """Stop keeping the latest of ``robot_id``'s streams: its subscriptions are undeclared, so nothing it
        publishes from now on reaches this session or is decoded. What was kept stays in ``latest`` (its age
        grows: :meth:`Robot.status <user_peer.robot.Robot.status>` shows it). :meth:`robot` follows it again (its
        latched path comes again at once). True when it was followed."""
        with self._lock:
            subs = self._subs.pop(robot_id, None)
        if subs is None:
            return False
        for sub in subs:
            try:
                sub.undeclare()
            except Exception:  # the session closed under us: nothing is delivered either way
                pass
        return True

    def _on_object_pose(self, key: str, msg: Any) -> None:
        self.latest.put(keys.object_pose_all(self.world, keys.parse(key).subject), msg)
