"""/tf and /tf_static from the bridge: the frame tree of ``export --to ros2``, REP 105's, rooted at ``map``.

The frames are :class:`user_peer.openfmt.frames.FrameTracker`'s, the export's: per base ``map -> ID/odom ->
ID/base_link`` (the identity, then its pose) with ``ID/laser`` and ``ID/sonar`` on ``ID/base_link``; per arm its
URDF's links under ``ID/`` (the root link bolted to ``map``, each link in its parent link's frame by forward
kinematics from its JointState, as robot_state_publisher sends them, so RViz's RobotModel with ``tf_prefix ID/``
places the ``/ID/robot_description`` links); each frame's stamps never go back. Every transform goes on ``/tf``
as the export writes it; the frames that never move (``ID/odom`` and the sensor mounts, ``frames.FIXED``) also
go once on ``/tf_static`` (transient local), so a node that starts later has them at once, with each sonar
transducer's ``ID/sonar_I`` under ``ID/sonar``. ``/tf_static`` keeps one message, the whole set: when the world
description draws a robot again (its poses came first and it was drawn from a guess: a mobile base where it is an
arm, a base without its sonar), its mounts are set again from the new drawing and the whole set sent again, so
the latched set never keeps a frame the described robot does not have.

``tf2_msgs`` is not among ROS 2 Kilted's wheels on PyPI: :mod:`user_peer.ros2.msgbuild` builds it into the
environment (``make test`` does; a ROS 2 install from apt has it). Without it nothing is published here and
``available`` is False (the bridge says so once at start, with the command that builds it).
"""

from __future__ import annotations

import threading
from typing import Any, Callable

from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from fabric.interfaces import WorldInfo
from user_peer.catalog import RobotCatalog
from user_peer.openfmt.frames import FIXED, MAP, Frame, FrameTracker, key_owner
from user_peer.ros2.direct import stamp
from user_peer.ros2.names import frame_prefix
from user_peer.ros2.ranges import transducer_frames

__all__ = ["TfOut", "tf_message_class", "transform", "TF_QOS", "TF_STATIC_QOS", "MAP"]

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
TF_STATIC_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""tf2's own QoS: /tf reliable and deep, /tf_static latched for late joiners."""


def tf_message_class() -> type | None:
    """``tf2_msgs.msg.TFMessage`` where it is importable (built by :mod:`user_peer.ros2.msgbuild`, or a ROS 2
    install's), else None."""
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    return TFMessage


def transform(f: Frame, ns: int, prefix: str = "") -> TransformStamped:
    """One frame as a ``geometry_msgs/TransformStamped``: ``f.child`` in ``f.parent``, stamped ``ns``, both frames
    under ``prefix`` (a namespace's, :mod:`user_peer.ros2.names`)."""
    t = TransformStamped()
    stamp(t.header, ns, prefix + f.parent)
    t.child_frame_id = prefix + f.child
    tr, rot = t.transform.translation, t.transform.rotation
    tr.x, tr.y, tr.z = (float(v) for v in f.translation)
    rot.x, rot.y, rot.z, rot.w = (float(v) for v in f.rotation)
    return t


class TfOut:
    """Publishes the frames robot state gives; ``publisher(topic, qos)`` makes the publishers (the node's by
    default; the test of the path without tf2_msgs gives its own)."""

    def __init__(
        self,
        node: Any,
        catalog: RobotCatalog,
        *,
        namespace: str = "",
        message: type | None = None,
        publisher: Callable[[str, QoSProfile], Any] | None = None,
    ) -> None:
        self.message = message if message is not None else tf_message_class()
        self.available = self.message is not None
        self.frames = FrameTracker(catalog)
        self._static: dict[str, Frame] = {}  # child -> the static frame last sent on /tf_static
        self._static_lock = threading.Lock()  # robot state's threads and the description's share the set
        self.sent = 0
        ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
        self.prefix = frame_prefix(namespace)
        self.topics = (f"{ns}/tf", f"{ns}/tf_static")
        self._pub = self._static_pub = None
        if self.available:
            make = publisher or (lambda topic, qos: node.create_publisher(self.message, topic, qos))
            self._pub, self._static_pub = make(self.topics[0], TF_QOS), make(self.topics[1], TF_STATIC_QOS)

    def _send_static(self, ns: int) -> None:
        """Every static frame in one message: /tf_static keeps only the last (depth 1), as tf2's broadcaster does."""
        self._static_pub.publish(
            self.message(transforms=[transform(f, ns, self.prefix) for f in self._static.values()])
        )

    def describe(self, info: WorldInfo) -> None:
        """The world's description: where arms stand, what each robot is; each sonar transducer's frame on
        /tf_static (:func:`user_peer.ros2.ranges.transducer_frames`), once, and again when it changes."""
        redrawn = self.frames.describe(info)
        if not self.available:
            return
        with self._static_lock:
            before = dict(self._static)
            for rid in redrawn:  # a guessed drawing's mounts give way to the described robot's
                for child in [c for c in self._static if c.startswith(f"{rid}/") and c.endswith(FIXED)]:
                    del self._static[child]
                self._static.update((f.child, f) for f in self.frames.mounts(rid))
            self._static.update(
                (f.child, f) for r in info.robots if r.sonar is not None for f in transducer_frames(r.id, r.sonar)
            )
            if self._static != before:
                self._send_static(0)

    def on_state(self, key: str, msg: Any, ns: int) -> None:
        """A robot's state: its frames, stamped ``ns`` (robot state comes one message at a time per key)."""
        if not self.available:
            return
        frames = self.frames.frames(key, msg, ns)
        if not frames:
            return
        self._pub.publish(self.message(transforms=[transform(f, ns, self.prefix) for f in frames]))
        self.sent += 1
        owner = key_owner(key)
        if owner is None or not any(f.child.endswith(FIXED) for f in frames):
            return
        with self._static_lock:  # the drawing's mounts now: a description may have drawn it again since ``frames``
            mounts = [f for f in self.frames.mounts(owner[1]) if self._static.get(f.child) != f]
            if mounts:
                self._static.update((f.child, f) for f in mounts)
                self._send_static(ns)
