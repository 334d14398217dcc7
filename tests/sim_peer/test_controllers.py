"""Properties of the controllers for any targets: limits and speeds are never exceeded, targets are reached."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
import pytest

import robots
from sim_peer.controllers import ArmController, BaseController

ARM = robots.load("meca500")
BASE = robots.load("reeman").base

angles = st.lists(st.floats(-10, 10, allow_nan=False), min_size=6, max_size=6)


@pytest.mark.slow
@settings(max_examples=50, deadline=None)
@given(angles, angles, st.floats(0.05, 1.0))
def test_arm_stays_in_range_under_its_speed_limits_and_reaches_the_clamped_target(first, second, scale):
    c = ArmController(ARM.joint_names, ARM.lower, ARM.upper, ARM.max_speed)
    vmax = np.array(ARM.max_speed)
    dt = 0.002
    for target in (first, second):
        c.set_target(target, scale)
        for _ in range(int(6.0 / scale / dt)):
            prev = c.q.copy()
            c.step(dt)
            assert np.all(np.abs(c.q - prev) <= vmax * scale * dt * (1 + 1e-9))
            assert np.all(c.q >= ARM.lower) and np.all(c.q <= ARM.upper)
            if not c.moving and np.array_equal(c.q, c.target):
                break
        np.testing.assert_allclose(c.q, np.clip(target, ARM.lower, ARM.upper), atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.floats(-1, 1), st.floats(-1.5, 1.5))
def test_base_respects_speed_and_acceleration_limits(v, w):
    b = BaseController(BASE)
    b.twist(v, w)
    dt = 0.002
    pv, pw = 0.0, 0.0
    for _ in range(1500):
        b.step(dt)
        assert abs(b.v) <= BASE.max_speed + 1e-12 and abs(b.omega) <= BASE.max_omega + 1e-12
        assert abs(b.v - pv) <= BASE.max_accel * dt + 1e-12 and abs(b.omega - pw) <= BASE.max_alpha * dt + 1e-12
        pv, pw = b.v, b.omega
    assert math.isclose(b.v, v, abs_tol=1e-9) and math.isclose(b.omega, w, abs_tol=1e-9)
    # wheel speeds are the differential-drive inverse kinematics of (v, omega)
    half = BASE.wheel_separation / 2
    np.testing.assert_allclose(b.wheel_speeds, [(v - w * half) / BASE.wheel_radius, (v + w * half) / BASE.wheel_radius])


def test_a_resumed_twist_clock_times_out_when_the_original_would():
    """A standby carries the twist timeout's count on (sim_peer.physics.robot_kinds restore), through the public method."""
    dt, n = 0.01, 30
    first = BaseController(BASE, twist_timeout=0.5)
    first.twist(0.2, 0.0)
    for _ in range(n):
        first.step(dt)
    assert math.isclose(first.since_twist, n * dt)
    second = BaseController(BASE, twist_timeout=0.5)
    second.twist(0.2, 0.0)
    second.resume_twist_clock(first.since_twist)
    steps = []
    for c in (first, second):
        k = 0
        while c.twists_expired == 0:
            c.step(dt)
            k += 1
        steps.append(k)
    assert steps[0] == steps[1]  # the same step on both (0.3 s held, ~0.2 s more reaches the 0.5 s timeout)
    assert abs(steps[0] * dt - 0.2) <= dt + 1e-9


@settings(max_examples=30, deadline=None)
@given(st.floats(-1, 1), st.floats(-1.5, 1.5))
def test_a_braking_base_slows_to_zero_within_its_limits_and_forgets_its_twist(v, w):
    """Its owner let go (SimRobot.halt): no velocity jump, at rest after v/max_accel (or w/max_alpha), and stays there."""
    b = BaseController(BASE)
    b.twist(v, w)
    dt = 0.002
    for _ in range(1500):
        b.step(dt)
    b.brake()
    assert (b.v_cmd, b.omega_cmd, b.follower) == (0.0, 0.0, None)
    pv, pw = b.v, b.omega
    steps = math.ceil(max(abs(v) / BASE.max_accel, abs(w) / BASE.max_alpha) / dt) + 1
    for _ in range(steps):
        b.step(dt)
        assert abs(b.v - pv) <= BASE.max_accel * dt + 1e-12 and abs(b.omega - pw) <= BASE.max_alpha * dt + 1e-12
        assert abs(b.v) <= abs(pv) + 1e-12 and abs(b.omega) <= abs(pw) + 1e-12  # only ever slower
        pv, pw = b.v, b.omega
    assert (b.v, b.omega) == (0.0, 0.0) and not b.moving


def _played(c: ArmController, seconds: float, dt: float = 0.01) -> list[np.ndarray]:
    out = []
    for _ in range(int(round(seconds / dt))):
        c.step(dt)
        out.append(c.q.copy())
    return out


def test_a_trajectory_is_played_in_the_sims_time_through_its_points_from_where_the_arm_was():
    c = ArmController(ARM.joint_names, ARM.lower, ARM.upper, ARM.max_speed)
    c.teleport(np.full(6, 0.1))
    mid, end = np.full(6, 0.4), np.full(6, 0.2)
    assert c.set_trajectory([1.5, 3.0], [mid, end]) is None
    np.testing.assert_allclose(c.goal, end)  # what a standby is given
    seen = _played(c, 1.5)
    np.testing.assert_allclose(seen[74], 0.1 + 0.3 * 0.75 / 1.5, atol=1e-9)  # halfway to mid at 0.75 s
    np.testing.assert_allclose(seen[-1], mid, atol=1e-9)  # at mid at 1.5 s, not before
    assert c.moving and c.playing is not None
    seen = _played(c, 1.6)
    np.testing.assert_allclose(seen[149], end, atol=1e-9)  # at the end at 3.0 s
    assert not c.moving and c.playing is None
    c.step(0.01)
    assert c.idle


def test_a_trajectory_that_holds_a_point_is_still_playing_and_a_stop_or_a_target_ends_it():
    c = ArmController(ARM.joint_names, ARM.lower, ARM.upper, ARM.max_speed)
    c.set_trajectory([1.0, 2.0, 3.0], [np.zeros(6), np.zeros(6), np.full(6, 0.3)])
    _played(c, 1.5)
    assert not c.idle and c.moving  # still, but the ownership gate must not hand it over mid-trajectory
    c.stop()
    _played(c, 0.1)
    assert c.playing is None and not c.moving
    c.set_trajectory([1.0], [np.full(6, 0.3)])
    c.set_target(np.zeros(6))
    assert c.playing is None


def test_a_trajectory_is_clamped_to_the_range_never_faster_than_the_limits_and_bad_ones_are_refused():
    from sim_peer.controllers import CommandRejected

    c = ArmController(ARM.joint_names, ARM.lower, ARM.upper, ARM.max_speed)
    far = np.array(ARM.upper) + 1.0
    clamp = c.set_trajectory([0.01], [far])  # asked for at once: reached at the speed limits, clamped
    assert clamp is not None and clamp.what == tuple(ARM.joint_names) and clamp.applied == tuple(ARM.upper)
    vmax = np.array(ARM.max_speed)
    prev = c.q.copy()
    for _ in range(2000):
        c.step(0.002)
        assert np.all(np.abs(c.q - prev) <= vmax * 0.002 * (1 + 1e-9))
        prev = c.q.copy()
    for times, points, reason in (
        ([1.0], [np.zeros(5)], "wrong_joint_count"),
        ([1.0, 2.0], [np.zeros(6)], "wrong_joint_count"),
        ([float("nan")], [np.zeros(6)], "not_finite"),
        ([2.0, 1.0], [np.zeros(6), np.zeros(6)], "bad_value"),
        ([-1.0], [np.zeros(6)], "bad_value"),
    ):
        with pytest.raises(CommandRejected) as err:
            c.set_trajectory(times, points)
        assert err.value.reason == reason, (times, err.value)
