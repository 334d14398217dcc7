"""A ROS cmd_vel checked before it is sent (user_peer/ros2/twist.py, issue 46): not finite or absurd is refused
with its reason, above the base's limit is sent with a note saying the sim clamps it, within it passes quietly."""

from __future__ import annotations

import math

import pytest

from fabric.interfaces.sensors import BaseInfo
from user_peer.ros2.commands import CommandError
from user_peer.ros2.twist import base_limits, twist_check

BASE = BaseInfo(
    radius=0.3, wheel_separation=0.4, wheel_radius=0.08, max_speed=1.0, max_omega=1.5, max_accel=1.0, max_alpha=3.0
)


@pytest.mark.parametrize("v, omega", [(math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan)])
def test_a_twist_that_is_not_finite_is_refused_even_without_limits(v, omega):
    for base in (BASE, None):
        with pytest.raises(CommandError, match="not finite"):
            twist_check(v, omega, base)


def test_a_twist_ten_times_the_limit_is_refused_as_a_unit_mistake():
    with pytest.raises(CommandError, match="linear.x 500 m/s is more than 10 times the base's limit 1 m/s"):
        twist_check(500.0, 0.0, BASE)
    with pytest.raises(CommandError, match="angular.z -90 rad/s"):
        twist_check(0.0, -90.0, BASE)


def test_above_the_limit_is_sent_with_the_clamp_told_and_within_it_quietly():
    assert twist_check(2.0, -2.0, BASE) == (
        "linear.x 2 m/s clamped by the sim to 1 m/s (the base's limit); "
        "angular.z -2 rad/s clamped by the sim to -1.5 rad/s (the base's limit)"
    )
    assert twist_check(1.0, -1.5, BASE) == "" and twist_check(50.0, 0.0, None) == ""


def test_the_limits_are_the_world_descriptions():
    class R:
        def __init__(self, rid, base):
            self.id, self.base = rid, base

    class Info:
        robots = [R("arm1", None), R("base1", BASE)]

    assert base_limits(Info(), "base1") is BASE and base_limits(Info(), "arm1") is None
    assert base_limits(None, "base1") is None and base_limits(Info(), "base9") is None
