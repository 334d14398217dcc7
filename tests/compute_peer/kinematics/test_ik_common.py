"""What the IK solvers share: one rotation-error formula, one degree format, the interfaces' wrap."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from hypothesis import given
from hypothesis import strategies as st

from compute_peer.kinematics import casadi_ik, closed_form_ik, ik_common, numerical_ik
from fabric.interfaces.geometry import wrap_angle


@given(st.floats(min_value=1e-12, max_value=math.pi), st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_the_rotation_error_is_the_angle_between_two_rotations(angle, axis):
    n = float(np.linalg.norm(axis))
    if n < 1e-3:
        return
    a = pin.rpy.rpyToMatrix(0.3, -0.2, 1.1)
    b = a @ pin.exp3(np.asarray(axis) / n * angle)
    # exact for tiny angles too, where acos((trace - 1) / 2) says 0
    assert math.isclose(ik_common.rotation_error(a, b), angle, rel_tol=1e-6, abs_tol=1e-15)


def test_the_solvers_share_the_helpers():
    assert casadi_ik.rotation_error is ik_common.rotation_error
    assert casadi_ik.degrees_text is ik_common.degrees_text and numerical_ik.degrees_text is ik_common.degrees_text
    assert closed_form_ik.wrap_angle is wrap_angle
    assert not hasattr(casadi_ik, "_rotation_error")
    assert ik_common.degrees_text(math.pi / 2) == "90.0\N{DEGREE SIGN}"
