"""The sonar ring's transducers as ``sensor_msgs/Range``: what the live bridge (:mod:`user_peer.ros2.ranges`) and
``export --to ros2`` (:class:`user_peer.openfmt.ros2.Ros2Writer`) both give, so a recording and the live world
read the same.

Transducer ``i`` of base ``ID`` is ``/ID/sonar_I`` in frame ``ID/sonar_I`` (a ROS name token may not start with
a digit, so not ``sonar/I``): on the ring's rim at its angle, x pointing out along its beam, a child of
``ID/sonar`` (the ring's centre), so that the range (measured by the sim from the rim) is true from that frame's
origin as ROS defines it. ``field_of_view`` is the sim's beam, a fan of three rays 15 degrees either side of the
axis (``sim_peer.sensors.Ultrasonic.BEAM``); a missing echo is +inf (REP 117), as in the ring's LaserScan.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from user_peer.openfmt.frames import Frame, yaw_quat_xyzw

__all__ = ["BEAM_HALF_WIDTH", "ULTRASOUND", "transducer_name", "transducer_frames", "range_value"]

BEAM_HALF_WIDTH = math.radians(15.0)
"""Half the field of view of one transducer: the sim's fan (``sim_peer.sensors.Ultrasonic.BEAM``)."""

ULTRASOUND = 0
"""``sensor_msgs/Range.ULTRASOUND``."""


def transducer_name(i: int) -> str:
    """The last part of transducer ``i``'s topic and frame: ``sonar_3``."""
    return f"sonar_{i}"


def transducer_frames(rid: str, angles: Iterable[float], radius: float) -> list[Frame]:
    """Each transducer's frame in ``rid/sonar`` (the ring's centre, at its height): on the rim at its angle, x out."""
    r = float(radius)
    return [
        Frame(f"{rid}/sonar", f"{rid}/{transducer_name(i)}", (r * math.cos(a), r * math.sin(a), 0.0), yaw_quat_xyzw(a))
        for i, a in enumerate(float(v) for v in angles)
    ]


def range_value(r: float, miss: float) -> float:
    """A transducer's range: +inf at or beyond ``miss`` (the ring's ``range_max`` less the tolerance), else ``r``."""
    return math.inf if r >= miss else float(r)
