"""Robot models for ROS 2: ``/NS/ROBOT/robot_description``, each robot's URDF, latched.

RViz's RobotModel display, robot_state_publisher and MoveIt read a robot's model from a latched
``std_msgs/String`` named ``robot_description``. The bridge publishes one per robot of the world, from its type's
URDF in ``robots/`` (the Meca500's, the Reeman base's, or an arm ``robofabric robots add`` installed: its folder keeps
its URDF), so the joints are named as ``joint_states`` names them. A mesh given by a path relative to the URDF (an
installed arm's copied meshes) becomes a ``file://`` URI, which RViz resolves on this machine; ``package://`` URIs are
left as they are. A robot type with no URDF gets no topic, said once in the log.
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

import robots
from user_peer.openfmt.ros2 import ros_topic

__all__ = ["ModelsOut", "robot_description"]

log = logging.getLogger("robofabric.ros2")

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""robot_state_publisher's own QoS for robot_description: a node that starts later still gets it."""


def robot_description(urdf: Path) -> str:
    """The URDF text of ``urdf`` as ROS tools take it: relative mesh file names made absolute ``file://`` URIs."""
    doc = ET.parse(urdf).getroot()
    for mesh in doc.iter("mesh"):
        name = mesh.get("filename", "")
        if name and "://" not in name:
            mesh.set("filename", (urdf.parent / name).resolve().as_uri())
    return ET.tostring(doc, encoding="unicode")


class ModelsOut:
    """One latched ``robot_description`` publisher per robot of the world (``describe`` with each description)."""

    def __init__(self, node: Node, namespace: str = "") -> None:
        self.node = node
        self.namespace = namespace.strip("/")
        self._pubs: dict[str, Any] = {}  # robot id -> its publisher
        self._texts: dict[str, str | None] = {}  # robot type -> its URDF text (None: the type has none here)

    def _text(self, rtype: str) -> str | None:
        if rtype not in self._texts:
            text = None
            try:
                d = robots.load(rtype)
                if d.urdf_path is not None:
                    text = robot_description(d.urdf_path)
                else:
                    log.info("robot type %s has no URDF: no robot_description for it", rtype)
            except (robots.DescriptionError, ET.ParseError, OSError) as exc:
                log.warning("no robot_description for robot type %s: %s", rtype, exc)
            self._texts[rtype] = text
        return self._texts[rtype]

    def describe(self, info: Any) -> None:
        """Publish the model of each robot of ``info`` not yet published; drop those of robots that left."""
        ids = {r.id for r in info.robots}
        for r in info.robots:
            if r.id in self._pubs:
                continue
            text = self._text(r.type)
            if text is None:
                continue
            pub = self.node.create_publisher(
                String, ros_topic("/".join([self.namespace, r.id, "robot_description"])), LATCHED
            )
            pub.publish(String(data=text))
            self._pubs[r.id] = pub
        for rid in [rid for rid in self._pubs if rid not in ids]:
            self.node.destroy_publisher(self._pubs.pop(rid))
