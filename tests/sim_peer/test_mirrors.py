"""Mirrors: a robot another sim simulates, as a body this sim's sensors see (sim_peer/mirrors.py)."""

from __future__ import annotations

import math
import threading
from dataclasses import replace

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import Pose, WorldInfo
from fabric.testing import wait_until
from sim_peer.mirroring import MirrorFeed
from sim_peer.world import SimWorld

FORWARD = 120  # the ray straight ahead of a 240-ray LIDAR (reeman: 240 rays over 360 deg, -x first)


@pytest.fixture
def warehouse() -> SimWorld:
    w = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=2)
    w.step(10)
    return w


def ahead(w: SimWorld) -> float:
    return float(np.median(w.scan("base0")[FORWARD - 2:FORWARD + 3]))


def test_a_mirrored_robot_is_seen_by_the_lidar_where_its_sim_says_it_is(warehouse):
    free = ahead(warehouse)
    assert free > 3.5  # nothing within 3.5 m straight ahead in the warehouse
    assert warehouse.mirror("base9", radius=0.3, height=0.5, position=[2.0, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b")
    at2 = ahead(warehouse)
    assert at2 < free - 2.0
    warehouse.mirror("base9", radius=0.3, height=0.5, position=[3.0, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b")
    assert ahead(warehouse) == pytest.approx(at2 + 1.0, abs=0.02)  # it moved 1 m away: the LIDAR sees it move
    warehouse.mirror("base9", radius=0.5, height=0.5, position=[3.0, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b")
    assert ahead(warehouse) == pytest.approx(at2 + 0.8, abs=0.02)  # resized to a wider footprint
    assert warehouse.unmirror(source="sim-b") == ["base9"]
    assert ahead(warehouse) == pytest.approx(free, abs=1e-6)


def test_the_bumper_stops_a_base_before_a_mirrored_robot(warehouse):
    warehouse.mirror("base9", radius=0.3, height=0.5, position=[1.5, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b")
    base = warehouse.robot("base0")
    base.twist(0.5, 0.0)
    for _ in range(int(4.0 / warehouse.dt)):
        warehouse.step()
    assert warehouse.collisions and warehouse.collisions[0][0] == "base0"
    assert not base.moving and base.ctrl.x + 0.05 + 0.25 < 1.5 - 0.3  # stopped short of the mirror's shell


def test_slots_are_bounded_and_own_robots_or_bad_poses_are_not_mirrored(warehouse):
    pose = dict(radius=0.3, height=0.5, quaternion=[1, 0, 0, 0], source="sim-b")
    assert warehouse.mirror("a", position=[5, 5, 0], **pose) and warehouse.mirror("b", position=[6, 5, 0], **pose)
    assert not warehouse.mirror("c", position=[7, 5, 0], **pose) and warehouse.mirrors.refused == 1  # two slots
    assert not warehouse.mirror("base0", position=[5, 5, 0], **pose)  # this sim's own robot
    assert not warehouse.mirror("a", position=[math.nan, 0, 0], **pose)
    assert warehouse.unmirror("a") == ["a"] and warehouse.mirror("c", position=[7, 5, 0], **pose)  # a freed slot is reused
    assert sorted(warehouse.mirrors.held()) == ["b", "c"]


def test_a_world_without_mirror_slots_mirrors_nothing():
    w = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False)
    assert w.mirrors.slots == 0
    assert not w.mirror("base9", radius=0.3, height=0.5, position=[2, 0, 0], quaternion=[1, 0, 0, 0])


# ---------------------------------------------------------------------- the feed, over real sessions


def _other_sim_part(world_name: str, sim_id: str) -> WorldInfo:
    """What another sim of the world serves for its one base: its description, as its own sim would give it."""
    other = SimWorld("warehouse", ["reeman:base9@3,0"], scene_robots=False)
    info = replace(other.robot("base9").describe(), sim=sim_id)
    return WorldInfo(world=world_name, scene="warehouse", timestep=other.dt, rates={}, robots=(info,))


def test_the_feed_mirrors_another_sims_base_from_its_poses_and_hides_it_when_that_sim_goes(world, connect):
    mine = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=2)
    lock = threading.RLock()
    here = connect(kind="sim", peer_id="sim-a")
    other = connect(kind="sim", peer_id="sim-b")
    part = _other_sim_part(world, "sim-b")
    key = keys.robot_pose(world, "base9")
    free = ahead(mine)
    with MirrorFeed(here, mine, lock, describe=lambda: part, stale_s=30.0) as feed:
        def put(x: float) -> None:
            other.publish(key, Pose(np.array([x, 0.0, 0.0]), np.array([1.0, 0.0, 0.0, 0.0]), header=other.header(key)))

        wait_until(lambda: put(2.0) or "base9" in mine.mirrors.held(), timeout=10, interval=0.05, what="base9 mirrored",
                   seen=lambda: feed.counters)
        wait_until(lambda: put(2.0) or ahead(mine) < free - 2.0, timeout=5, what="the LIDAR seeing base9 at 2 m")
        at2 = ahead(mine)
        wait_until(lambda: put(3.0) or abs(ahead(mine) - (at2 + 1.0)) < 0.02, timeout=5, what="the LIDAR seeing base9 move to 3 m",
                   seen=lambda: ahead(mine))
        assert feed.lag_ms and feed.counters["shown"] == 1
        put(0.0)  # this sim's own robots' poses (its own session's) are never mirrored: not even heard (remote only)
        other.close()  # sim-b goes: its token with it
        wait_until(lambda: "base9" not in mine.mirrors.held(), timeout=10, what="base9's mirror hidden when sim-b left")
        assert ahead(mine) == pytest.approx(free, abs=1e-6)


def test_a_mirror_whose_robot_falls_silent_is_hidden(world, connect):
    mine = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=2)
    now = [0.0]
    other = connect(kind="sim", peer_id="sim-b")
    part = _other_sim_part(world, "sim-b")
    key = keys.robot_pose(world, "base9")
    with MirrorFeed(connect(kind="sim", peer_id="sim-a"), mine, threading.RLock(), describe=lambda: part, stale_s=2.0,
                    clock=lambda: now[0]) as feed:
        def put() -> None:
            other.publish(key, Pose(np.array([2.0, 0.0, 0.0]), np.array([1.0, 0, 0, 0]), header=other.header(key)))

        wait_until(lambda: put() or "base9" in mine.mirrors.held(), timeout=10, interval=0.05, what="base9 mirrored")
        assert feed.sweep() == []
        now[0] = 2.5  # no pose for longer than stale_s: hidden by the feed's own sweep, or by this one
        wait_until(lambda: feed.sweep() is not None and "base9" not in mine.mirrors.held(), timeout=5, what="base9 hidden")
        assert feed.counters["hidden"] == 1
