"""Arm kinematics on a Pinocchio model built from the robots package's URDF.

FK, the paper's geometric Jacobian (Eq. 3-6), twists, Eq. 7 joint speed
magnitudes and an IK that refuses (``NoIKSolution``) instead of returning a
silent best effort; :func:`solve` is the IK entry point (the Meca500's closed
form, or Levenberg-Marquardt for any arm).
"""

from compute_peer.kinematics.ik import (
    IKSolution,
    in_base_column,
    meca500_ik,
    solve,
    solve_numerical,
)
from compute_peer.kinematics.model import ArmModel, NoIKSolution

__all__ = ["ArmModel", "IKSolution", "NoIKSolution", "in_base_column", "meca500_ik", "solve", "solve_numerical"]
