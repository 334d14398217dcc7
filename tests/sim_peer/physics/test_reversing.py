"""Reversing where the robot can reverse: a Hybrid A* plan with backwards stretches is followed backwards by the
sim's follower (issue 44)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from compute_peer.navigation import PlannerSettings, VehicleModel, plan_path
from compute_peer.navigation.grid import make_grid
import robots
from sim_peer.physics.pure_pursuit import PurePursuit
from sim_peer.physics.world import SimWorld


def test_a_stretch_whose_headings_point_against_its_travel_is_driven_backwards():
    x = np.concatenate([np.linspace(0.0, -1.0, 21), np.linspace(-0.95, 0.5, 30)])  # back 1 m, then forwards
    pp = PurePursuit(x, np.zeros_like(x), np.zeros_like(x), max_speed=1.0, max_omega=1.5, max_accel=1.0)
    assert pp.backwards == [True, False]
    fwd = PurePursuit(x[21:], np.zeros(30), np.zeros(30), max_speed=1.0, max_omega=1.5, max_accel=1.0)
    assert fwd.backwards == [False]
    assert PurePursuit(x, np.zeros_like(x), None, max_speed=1.0, max_omega=1.5, max_accel=1.0).backwards == [
        False,
        False,
    ]


def test_a_reversing_plan_is_followed_backwards():
    cells = np.zeros((120, 120), dtype=np.uint8)  # 6 m x 6 m of open floor about the warehouse's centre
    start, goal = (0.0, 0.0, 0.0), (-1.0, 0.0, 0.0)  # one metre straight behind the base, facing the same way
    vehicle = VehicleModel(robot_radius=0.3, turning_radius=0.5, allow_reverse=True)
    plan = plan_path(make_grid(cells, 0.05, (-3.0, -3.0)), start, goal, settings=PlannerSettings(vehicle=vehicle))
    assert plan.length == pytest.approx(1.0, abs=0.05)  # straight back, not a loop around
    world = SimWorld("warehouse", seed=1)
    base = world.robots["base1"]
    base.path(plan.x, plan.y, plan.theta)
    assert base.ctrl.follower.backwards == [True]
    speeds, yaws = [], []
    for _ in range(int(6.0 / world.dt / 25)):
        world.step(25)
        speeds.append(base.ctrl.v)
        yaws.append(base.ctrl.yaw)
        if base.ctrl.follower is None:
            break
    assert base.ctrl.follower is None  # followed to its end
    assert math.hypot(base.ctrl.x - goal[0], base.ctrl.y - goal[1]) < 0.1
    assert min(speeds) < -0.3 and max(speeds) <= 1e-6  # backwards all the way
    assert max(abs(math.remainder(y, 2 * math.pi)) for y in yaws) < 0.2  # it never turned around
    assert robots.load("reeman").base.reverse is False  # the description's default: plans forwards unless asked


def test_the_description_says_whether_a_base_may_reverse():
    from robots.description import DescriptionError, _base

    base = {
        "radius": 0.3,
        "wheel_separation": 0.4,
        "wheel_radius": 0.08,
        "max_speed": 1.0,
        "max_omega": 1.5,
        "max_accel": 1.0,
        "max_alpha": 3.0,
    }
    assert _base({"base": base}, "t").reverse is False
    assert _base({"base": {**base, "reverse": True}}, "t").reverse is True
    with pytest.raises(DescriptionError, match="reverse must be true or false"):
        _base({"base": {**base, "reverse": "yes"}}, "t")
    world = SimWorld("warehouse", seed=1)
    assert world.robots["base1"].describe().base.reverse == 0  # what srv/world tells the compute peer
