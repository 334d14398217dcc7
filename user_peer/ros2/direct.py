"""The bridge's hot path: a fabric message straight into a reused rclpy message, no dict in between.

``user_peer.openfmt.ros2.ros2_message`` is the one definition of what a fabric message is in ROS 2 (the MCAP
export writes its dicts); filling an rclpy message from that dict costs a dict per message, a list per array and
a Python loop per field, which at class scale (8 robots, about 1,300 messages a second) is most of what the
bridge spends in Python. These builders set the same fields directly: numpy arrays go into the message's
``array.array`` fields through their buffers, the names are the fabric's tuple, and each joint-state, scan
and odometry topic keeps one message that is refilled for each sample (``publish`` serialises it at once, and
one topic's samples come from one zenoh subscription, one after another; a pose of a scene object, whose latched
history may cross its live samples, is built new). tests/user_peer/test_ros2_direct.py holds them equal to
``fill(ros2_message(...))`` field by field, so the live values stay the export's.

The stream kinds that are rare or large in structure (the map, a path, scene objects) keep the export's dicts
(:func:`user_peer.ros2.fill.fill`): they come a few times a second at most.
"""

from __future__ import annotations

import array
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState, LaserScan

from fabric.interfaces import JointState as FabricJointState
from fabric.interfaces import Pose, Scan
from user_peer.openfmt.ros2 import MISS_TOLERANCE_M, ODOM_COVARIANCE, to_body
from user_peer.openfmt.frames import base_frame, ros_frame

__all__ = ["stamp", "joint_state", "laser_scan", "odometry", "pose_stamped"]

_EMPTY_D = array.array("d")
_EMPTY_F = array.array("f")
_COVARIANCE = np.array(ODOM_COVARIANCE, dtype=np.float64)


def stamp(header: Any, ns: int, frame: str) -> None:
    """Set a ``std_msgs/Header`` in place: ``ns`` since the epoch (of the clock the stamps use) and the frame."""
    header.stamp.sec = ns // 1_000_000_000
    header.stamp.nanosec = ns % 1_000_000_000
    header.frame_id = frame


def _doubles(a: np.ndarray) -> array.array:
    return array.array("d", np.ascontiguousarray(a, dtype=np.float64).tobytes())


def joint_state(out: JointState, robot: str, msg: FabricJointState, ns: int) -> JointState:
    """``out`` refilled with ``msg``: frame ``robot`` (the route's, ``ID/base_link``), names, positions and
    velocities, no efforts."""
    stamp(out.header, ns, robot)
    out.name = list(msg.names)
    out.position = _doubles(msg.q)
    out.velocity = _doubles(msg.dq)
    out.effort = _EMPTY_D
    return out


def laser_scan(
    out: LaserScan, frame: str, msg: Scan, ns: int, range_min: float, offset: float, scan_time: float = 0.0
) -> LaserScan:
    """``out`` refilled with ``msg``: a missing echo (the fabric's ``range_max``) is +inf, REP 117; ``offset``
    added to the other ranges and to the limits (a sonar's rim-to-centre radius), as the export does; ``scan_time``
    the sensor's period (``time_increment`` 0: the sim casts a scan's rays at one instant)."""
    stamp(out.header, ns, frame)
    n = int(msg.ranges_mm.shape[0])
    r = np.asarray(msg.ranges, dtype=np.float64)  # metres as the export reads them (float64), then float32 once
    ranges = np.where(r >= float(msg.range_max) - MISS_TOLERANCE_M, np.inf, r + offset).astype(np.float32)
    out.angle_min = float(msg.angle_min)
    out.angle_max = float(msg.angle_min + msg.angle_increment * max(n - 1, 0))
    out.angle_increment = float(msg.angle_increment)
    out.time_increment = 0.0
    out.scan_time = float(scan_time)
    out.range_min = float(range_min) + offset
    out.range_max = float(msg.range_max) + offset
    out.ranges = array.array("f", ranges.tobytes())
    out.intensities = _EMPTY_F
    return out


def _pose(out: Any, position: np.ndarray, q_wxyz: np.ndarray) -> None:
    p, o = out.position, out.orientation
    p.x, p.y, p.z = position.tolist()
    o.w, o.x, o.y, o.z = q_wxyz.tolist()


def pose_stamped(out: PoseStamped, msg: Pose, ns: int, prefix: str = "") -> PoseStamped:
    """``out`` refilled with ``msg`` (an arm's flange, a scene object) in its own frame (the world's is ``map``),
    under ``prefix`` (a namespace's, :mod:`user_peer.ros2.names`)."""
    stamp(out.header, ns, prefix + ros_frame(msg.frame))
    _pose(out.pose, msg.position, msg.quaternion)
    return out


def odometry(out: Odometry, robot: str, msg: Pose, ns: int, prefix: str = "") -> Odometry:
    """``out`` refilled with a base's pose (frame ``ID/odom``, child ``ID/base_link``, REP 105's, both under
    ``prefix``) and its twist turned from the world frame (the sim's velocities) into the base's, as REP 105 asks."""
    stamp(out.header, ns, f"{prefix}{robot}/odom")
    out.child_frame_id = prefix + base_frame(robot)
    _pose(out.pose.pose, msg.position, msg.quaternion)
    out.pose.covariance = out.twist.covariance = _COVARIANCE  # copied by the setter: the constant stays as it is
    lin, ang = out.twist.twist.linear, out.twist.twist.angular
    lin.x, lin.y, lin.z = to_body(msg.quaternion, msg.linear)
    ang.x, ang.y, ang.z = to_body(msg.quaternion, msg.angular)
    return out
