"""The sonar ring as ``sensor_msgs/Range``, one topic per transducer, as Nav2's range layer reads sonars.

The fabric sends a base's ring as one Scan on ``robot/ID/sonar`` (the bridge's ``/ID/sonar`` LaserScan, kept):
range ``i`` is the transducer at ``SonarInfo.angles[i]``, measured from the ring's rim. Here each transducer is
also a ``Range`` on ``/NS/ID/sonar_I`` in its own frame ``NS/ID/sonar_I``, as ``export --to ros2`` writes it
(names, frames, field of view and misses: :mod:`user_peer.openfmt.ros2_ranges`). ``/tf_static`` places those
frames under ``ID/sonar`` (the ring's centre), where ``tf2_msgs`` is importable (:mod:`user_peer.ros2.tf`).

A transducer's message is published only while a node subscribes to its topic: eight more messages per ring at
the scan rate would cost a class of eight bases about 1,300 publishes a second that nobody reads (the bridge's
CPU budget, docs/ros2.md "Benchmark"); asking a publisher for its subscribers takes about 5 microseconds.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Range

from fabric.interfaces import Scan, SonarInfo, WorldInfo
from user_peer.openfmt.frames import Frame
from user_peer.openfmt.ros2 import MISS_TOLERANCE_M, ros_topic
from user_peer.openfmt.ros2_ranges import BEAM_HALF_WIDTH, range_value, transducer_name
from user_peer.openfmt.ros2_ranges import transducer_frames as _frames
from user_peer.ros2.direct import stamp

__all__ = ["BEAM_HALF_WIDTH", "RangesOut", "transducer_frames", "transducer_name"]


def transducer_frames(rid: str, sonar: SonarInfo) -> list[Frame]:
    """Each transducer's frame in ``rid/sonar`` (the ring's centre, at its height): on the rim at its angle, x out."""
    return _frames(rid, sonar.angles, sonar.radius)


def _shape(s: SonarInfo) -> tuple:
    """What a ring's topics and fixed fields depend on (SonarInfo holds arrays, which == does not compare)."""
    return tuple(float(a) for a in s.angles), float(s.range_min), float(s.range_max)


class _Ring:
    """One base's transducers: a publisher and a reused message each."""

    def __init__(self, node: Any, topic: Callable[[str], str], frame: Callable[[str], str], sonar: SonarInfo) -> None:
        self.sonar = sonar
        self.pubs, self.msgs = [], []
        for i in range(len(sonar.angles)):
            m = Range()
            m.header.frame_id = frame(transducer_name(i))
            m.radiation_type = Range.ULTRASOUND
            m.field_of_view = 2 * BEAM_HALF_WIDTH
            m.min_range, m.max_range = float(sonar.range_min), float(sonar.range_max)
            self.pubs.append(node.create_publisher(Range, topic(transducer_name(i)), qos_profile_sensor_data))
            self.msgs.append(m)


class RangesOut:
    """The Range topics of every base with a sonar ring; ``describe`` follows the world's robots."""

    def __init__(self, node: Any, namespace: str = "", prefix: str = "") -> None:
        self.node = node
        self.ns = namespace.strip("/")
        self.prefix = prefix  # frame ids under the namespace (names.py)
        self._rings: dict[str, _Ring] = {}
        self.sent = 0

    def describe(self, info: WorldInfo) -> None:
        """A ring's topics for each base that has one (again if its ring changed); none for robots that left."""
        have = {r.id: r.sonar for r in info.robots if r.sonar is not None and len(r.sonar.angles)}
        for rid in [
            rid for rid, ring in self._rings.items() if rid not in have or _shape(ring.sonar) != _shape(have[rid])
        ]:
            self._drop(rid)
        for rid, sonar in have.items():
            if rid not in self._rings:
                self._rings[rid] = _Ring(
                    self.node,
                    lambda leaf, r=rid: ros_topic("/".join((self.ns, r, leaf))),
                    lambda leaf, r=rid: f"{self.prefix}{r}/{leaf}",
                    sonar,
                )

    def _drop(self, rid: str) -> None:
        for pub in self._rings.pop(rid).pubs:
            self.node.destroy_publisher(pub)

    def on_scan(self, rid: str, key: str, scan: Scan, ns: int) -> None:
        """A ring's Scan (``robot/ID/sonar``; other scans pass by): each transducer a Range, where a node listens."""
        ring = self._rings.get(rid)
        if ring is None or not key.endswith("/sonar"):
            return
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        miss = float(scan.range_max) - MISS_TOLERANCE_M
        for pub, msg, r in zip(ring.pubs, ring.msgs, ranges.tolist()):
            if pub.get_subscription_count() == 0:
                continue
            stamp(msg.header, ns, msg.header.frame_id)
            msg.range = range_value(r, miss)
            pub.publish(msg)
            self.sent += 1

    def close(self) -> None:
        for rid in list(self._rings):
            self._drop(rid)
