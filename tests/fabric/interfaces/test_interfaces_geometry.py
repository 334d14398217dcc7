"""The one wrap_angle every peer uses: [-pi, pi) (or (-pi, pi] on request), same angle, arrays element-wise."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from fabric.interfaces import TWO_PI, wrap_angle

angles = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False)


@given(angles)
def test_wrapped_angle_is_in_range_and_the_same_direction(a):
    w = wrap_angle(a)
    assert -math.pi <= w < math.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)
    assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-9)


@given(st.floats(min_value=-math.pi, max_value=math.pi - 1e-9))
def test_an_angle_already_in_range_is_left_alone(a):
    # (just under pi, a + pi rounds to 2 pi and the angle comes back as -pi: the same direction)
    assert math.isclose(wrap_angle(a), a, abs_tol=1e-12)


@given(st.lists(angles, min_size=1, max_size=30))
def test_an_array_is_wrapped_element_wise(values):
    out = wrap_angle(np.array(values))
    assert isinstance(out, np.ndarray) and out.shape == (len(values),)
    assert out.tolist() == [wrap_angle(v) for v in values]


def test_the_ends_of_the_range():
    assert wrap_angle(math.pi) == -math.pi
    assert wrap_angle(-math.pi) == -math.pi
    assert wrap_angle(TWO_PI) == 0.0
    assert isinstance(wrap_angle(3.5), float)


@given(angles)
def test_including_pi_wraps_to_the_other_half_open_range(a):
    w = wrap_angle(a, include_pi=True)
    assert -math.pi < w <= math.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)
    assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-9)
    assert wrap_angle(np.array([a]), include_pi=True).tolist() == [w]


@given(st.floats(min_value=-math.pi, max_value=math.pi, exclude_min=True))
def test_including_pi_leaves_an_angle_in_range_bit_for_bit(a):
    # the closed-form IK's solutions stay exactly what they were: no rounding through a + pi
    assert wrap_angle(a, include_pi=True) == a
    assert wrap_angle(np.array([a]), include_pi=True).tolist() == [a]


def test_the_ends_of_the_range_including_pi():
    assert wrap_angle(math.pi, include_pi=True) == math.pi
    assert wrap_angle(-math.pi, include_pi=True) == math.pi
    assert wrap_angle(-TWO_PI, include_pi=True) == 0.0
    assert isinstance(wrap_angle(3.5, include_pi=True), float)


def test_the_peers_share_the_one_definition():
    from compute_peer.kinematics import closed_form_ik, ik_common
    from compute_peer.navigation import geometry as nav_geometry
    from sim_peer import controllers

    assert nav_geometry.wrap_angle is wrap_angle and controllers.wrap_angle is wrap_angle
    assert closed_form_ik.wrap_angle is wrap_angle and ik_common.TWO_PI is TWO_PI
    assert not hasattr(ik_common, "_wrap")


@given(st.floats(min_value=-math.pi + 1e-9, max_value=math.pi - 1e-9))
def test_yaw_and_quaternion_are_inverse_and_unit(yaw):
    from fabric.interfaces import quaternion_from_yaw, yaw_from_quaternion

    q = quaternion_from_yaw(yaw)
    assert math.isclose(float(np.linalg.norm(q)), 1.0, abs_tol=1e-12)
    assert math.isclose(yaw_from_quaternion(q), yaw, abs_tol=1e-9)
    assert math.isclose(yaw_from_quaternion(-q), yaw, abs_tol=1e-9)  # q and -q are the same rotation


def test_one_heading_helper_for_every_peer():
    import fabric.interfaces as fi
    from user_peer import geometry as views

    assert views.yaw_of is fi.yaw_from_quaternion
    assert fi.quaternion_from_yaw(math.pi / 2).tolist() == [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]
