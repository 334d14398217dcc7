"""Arm kinematics on a Pinocchio model built from the robots package's URDF.

FK, the paper's geometric Jacobian (Eq. 3-6), twists, Eq. 7 joint speed
magnitudes and a damped-least-squares IK that refuses (``Unreachable``)
instead of returning a silent best effort.
"""

from compute_peer.kinematics.model import ArmModel, Unreachable

__all__ = ["ArmModel", "Unreachable"]
