"""Navigation goals from ROS 2: RViz's "2D Goal Pose" planned with the world's planner and followed.

``/NS/ROBOT/goal_pose`` (``geometry_msgs/PoseStamped``) for each mobile base the bridge drives (``--drive``),
and ``/NS/goal_pose`` (RViz's default topic) for the one base it drives when there is exactly one. A goal is
planned as a user script plans (``Base.plan_to``: the compute peer's planner on ``map_name``, by default this
login's own map, the one ``Base.build_map`` builds, as a student's script would) and handed to the sim's
follower (``Base.follow``, not waited for). The compute peer publishes the plan on the robot's path key, which
the bridge gives to ROS as ``/NS/ROBOT/path``. A goal that cannot be done (not owned, a frame other than the
world's, no path) is refused on /rosout with the planner's reason. Planning takes seconds, so each goal runs
on a thread of its own, not in the rclpy executor; a newer goal's path replaces the older in the sim's follower.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node

from fabric import keys
from fabric.interfaces.geometry import yaw_from_quaternion
from user_peer.errors import FabricUserError
from user_peer.openfmt.ros2 import ros_topic
from user_peer.ros2.commands import CommandError
from user_peer.ros2.names import frame_prefix
from user_peer.ros2.navigate import NavigateActions

__all__ = ["GOAL_FRAMES", "GoalsIn", "goal_of"]

GOAL_FRAMES = ("", "map", "world")
"""Frames a goal may be given in: the bridge's root frame ``map`` (RViz's fixed frame, REP 105's; the fabric's maps
are in the world's coordinates), ``world`` (the fabric's name for the same plane), or none."""


def goal_of(msg: Any, prefix: str = "") -> tuple[float, float, float]:
    """(x, y, yaw) of a ``PoseStamped`` in the world's frame (under a namespace's ``prefix``, ``class1/map``, or
    not); :class:`CommandError` for another frame."""
    frame = msg.header.frame_id.strip("/")
    if frame not in GOAL_FRAMES and not (
        prefix and frame.startswith(prefix) and frame[len(prefix) :] in GOAL_FRAMES[1:]
    ):
        raise CommandError(
            f"goal_pose in frame {frame!r}: give it in '{prefix}map' (or '{prefix}world'), the bridge's fixed frame"
        )
    o = msg.pose.orientation
    return float(msg.pose.position.x), float(msg.pose.position.y), yaw_from_quaternion((o.w, o.x, o.y, o.z))


class GoalsIn:
    """The goal_pose subscriptions of the bases a bridge drives; each goal planned and followed on its thread."""

    def __init__(
        self,
        node: Node,
        namespace: str,
        qos: Any,
        check_owner: Callable[[str, str], Any],
        refuse: Callable[[str, str, str], None],
        map_name: str = "",
    ) -> None:
        self.node, self.namespace, self.qos = node, namespace.strip("/"), qos
        self.prefix = frame_prefix(namespace)
        self.check_owner, self.refuse = check_owner, refuse
        self.map_name = map_name
        self.actions = NavigateActions(
            node, namespace, self.prefix, check_owner, refuse, goal_of, map_name
        )  # navigate_to_pose
        self._bases: set[str] = set()
        self._shared: Any = None  # /NS/goal_pose, while exactly one base is driven
        self.followed = 0  # goals planned and handed to the follower

    def subscribe(self, rid: str) -> Any:
        """``rid``'s goal_pose subscription (the caller keeps it with the robot's command inputs)."""
        self._bases.add(rid)
        self.actions.serve(rid)
        if self._shared is None:
            self._shared = self.node.create_subscription(
                PoseStamped, ros_topic("/".join([self.namespace, "goal_pose"])), self._on_shared, self.qos
            )
        return self.node.create_subscription(
            PoseStamped,
            ros_topic("/".join([self.namespace, rid, "goal_pose"])),
            lambda m, r=rid: self.on_goal(r, m),
            self.qos,
        )

    def forget(self, rid: str) -> None:
        self._bases.discard(rid)
        self.actions.forget(rid)

    def close(self) -> None:
        self.actions.close()

    def _on_shared(self, msg: Any) -> None:
        if len(self._bases) != 1:
            self.refuse(
                "goal_pose",
                "goal_pose",
                f"the bridge drives {len(self._bases)} bases "
                f"({', '.join(sorted(self._bases)) or 'none'}): send the goal on /ROBOT/goal_pose",
            )
            return
        self.on_goal(next(iter(self._bases)), msg)

    def on_goal(self, rid: str, msg: Any) -> None:
        base = self.check_owner(rid, "goal_pose")
        if base is None:
            return
        try:
            goal = goal_of(msg, self.prefix)
        except CommandError as exc:
            self.refuse(rid, "goal_pose", str(exc))
            return
        threading.Thread(target=self._go, args=(rid, base, goal), name=f"ros2-goal-{rid}", daemon=True).start()

    def _go(self, rid: str, base: Any, goal: tuple[float, float, float]) -> None:
        try:
            name = self.map_name or keys.user_map("map", base.world.user)
            path = base.plan_to(*goal, map_name=name)
            base.follow(path, wait=False)
            self.followed += 1
            self.node.get_logger().info(
                f"goal for {rid} at ({goal[0]:.2f}, {goal[1]:.2f}): {len(path)} poses planned on map {name!r}, followed"
            )
        except (FabricUserError, ValueError) as exc:
            self.refuse(rid, "goal_pose", getattr(exc, "reason", str(exc)))
