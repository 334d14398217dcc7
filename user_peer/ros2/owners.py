"""Who owns each robot, on ROS 2: a latched ``std_msgs/String`` ``/NS/ROBOT/owner`` holding the owner's login.

A ROS user sees whether her bridge may drive a robot without leaving ROS: ``ros2 topic echo /base1/owner`` gives
``alice`` (the login that owns base1), or an empty string while it is free (or in a world without ownership). The
value is the bridge's replica of the robot's ownership record (``World.ownership``, which follows the authority),
looked at once a second with the world's description (:meth:`user_peer.ros2.bridge.Ros2Bridge.follow`), and
published when it changes. Transient local, as robot_description: a node that starts later gets the current
owner at once. Asking and giving up stay the bridge's ``--request`` (no ``std_srvs`` among the wheels for a
Trigger service).
"""

from __future__ import annotations

from typing import Any, Callable, Iterable

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from fabric.interfaces import OwnershipRecord
from user_peer.openfmt.ros2 import ros_topic

__all__ = ["OWNER_QOS", "OwnersOut", "owner_text"]

OWNER_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def owner_text(rec: OwnershipRecord | None) -> str:
    """The topic's value: the owner's login, "" when free or when the world has no record of the robot."""
    return rec.owner if rec is not None else ""


class OwnersOut:
    """One latched owner topic per robot; ``update`` publishes the owners that changed since the last call."""

    def __init__(self, node: Any, namespace: str = "") -> None:
        self.node = node
        self.ns = namespace.strip("/")
        self._pubs: dict[str, Any] = {}  # robot -> its publisher
        self._said: dict[str, str] = {}  # robot -> the owner last published
        self.sent = 0

    def update(self, robots: Iterable[str], record: Callable[[str], OwnershipRecord | None]) -> None:
        """Each robot's owner now (``record``: the ownership replica's), published when new; robots gone dropped."""
        now = set(robots)
        for rid in [r for r in self._pubs if r not in now]:
            self.node.destroy_publisher(self._pubs.pop(rid))
            self._said.pop(rid, None)
        for rid in sorted(now):
            text = owner_text(record(rid))
            if self._said.get(rid) == text:
                continue
            pub = self._pubs.get(rid)
            if pub is None:
                pub = self._pubs[rid] = self.node.create_publisher(
                    String, ros_topic("/".join((self.ns, rid, "owner"))), OWNER_QOS
                )
            pub.publish(String(data=text))
            self._said[rid] = text
            self.sent += 1
