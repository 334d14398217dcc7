"""Mirrors: a robot another sim simulates, as a body this sim's sensors see (sim_peer/mirrors.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_peer.world import SimWorld

FORWARD = 120  # the ray straight ahead of a 240-ray LIDAR (reeman: 240 rays over 360 deg, -x first)


@pytest.fixture
def world() -> SimWorld:
    w = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=2)
    w.step(10)
    return w


def ahead(w: SimWorld) -> float:
    return float(np.median(w.scan("base0")[FORWARD - 2:FORWARD + 3]))


def test_a_mirrored_robot_is_seen_by_the_lidar_where_its_sim_says_it_is(world):
    free = ahead(world)
    assert free > 3.5  # nothing within 3.5 m straight ahead in the warehouse
    assert world.mirror("base9", radius=0.3, height=0.5, position=[2.0, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b")
    at2 = ahead(world)
    assert at2 < free - 2.0
    world.mirror("base9", radius=0.3, height=0.5, position=[3.0, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b")
    assert ahead(world) == pytest.approx(at2 + 1.0, abs=0.02)  # it moved 1 m away: the LIDAR sees it move
    world.mirror("base9", radius=0.5, height=0.5, position=[3.0, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b")
    assert ahead(world) == pytest.approx(at2 + 0.8, abs=0.02)  # resized to a wider footprint
    assert world.unmirror(source="sim-b") == ["base9"]
    assert ahead(world) == pytest.approx(free, abs=1e-6)


def test_the_bumper_stops_a_base_before_a_mirrored_robot(world):
    world.mirror("base9", radius=0.3, height=0.5, position=[1.5, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b")
    base = world.robot("base0")
    base.twist(0.5, 0.0)
    for _ in range(int(4.0 / world.dt)):
        world.step()
    assert world.collisions and world.collisions[0][0] == "base0"
    assert not base.moving and base.ctrl.x + 0.05 + 0.25 < 1.5 - 0.3  # stopped short of the mirror's shell


def test_slots_are_bounded_and_own_robots_or_bad_poses_are_not_mirrored(world):
    pose = dict(radius=0.3, height=0.5, quaternion=[1, 0, 0, 0], source="sim-b")
    assert world.mirror("a", position=[5, 5, 0], **pose) and world.mirror("b", position=[6, 5, 0], **pose)
    assert not world.mirror("c", position=[7, 5, 0], **pose) and world.mirrors.refused == 1  # two slots
    assert not world.mirror("base0", position=[5, 5, 0], **pose)  # this sim's own robot
    assert not world.mirror("a", position=[math.nan, 0, 0], **pose)
    assert world.unmirror("a") == ["a"] and world.mirror("c", position=[7, 5, 0], **pose)  # a freed slot is reused
    assert sorted(world.mirrors.held()) == ["b", "c"]


def test_a_world_without_mirror_slots_mirrors_nothing():
    w = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False)
    assert w.mirrors.slots == 0
    assert not w.mirror("base9", radius=0.3, height=0.5, position=[2, 0, 0], quaternion=[1, 0, 0, 0])
