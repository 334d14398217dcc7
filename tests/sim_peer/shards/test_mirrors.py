"""Mirrors: a robot another sim simulates, as a body this sim's sensors see (sim_peer/physics/mirrors.py)."""

from __future__ import annotations

import math
import threading
from dataclasses import replace

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import JointState, Pose, RobotInfo, WorldInfo
from robofabric.testing import wait_until
from sim_peer.shards.mirroring import MirrorFeed
from sim_peer.physics.world import SimWorld

FORWARD = 120  # the ray straight ahead of a 240-ray LIDAR (reeman: 240 rays over 360 deg, -x first)


@pytest.fixture
def warehouse() -> SimWorld:
    w = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=2)
    w.step(10)
    return w


def ahead(w: SimWorld) -> float:
    return float(np.median(w.readings.scan("base0")[FORWARD - 2 : FORWARD + 3]))


def test_a_mirrored_robot_is_seen_by_the_lidar_where_its_sim_says_it_is(warehouse):
    free = ahead(warehouse)
    assert free > 3.5  # nothing within 3.5 m straight ahead in the warehouse
    assert warehouse.mirror(
        "base9", radius=0.3, height=0.5, position=[2.0, 0.0, 0.0], quaternion=[1, 0, 0, 0], source="sim-b"
    )
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
    assert warehouse.notes.collisions and warehouse.notes.collisions[0][0] == "base0"
    assert not base.moving and base.ctrl.x + 0.05 + 0.25 < 1.5 - 0.3  # stopped short of the mirror's shell


def test_slots_are_bounded_and_own_robots_or_bad_poses_are_not_mirrored(warehouse):
    pose = dict(radius=0.3, height=0.5, quaternion=[1, 0, 0, 0], source="sim-b")
    assert warehouse.mirror("a", position=[5, 5, 0], **pose) and warehouse.mirror("b", position=[6, 5, 0], **pose)
    assert not warehouse.mirror("c", position=[7, 5, 0], **pose) and warehouse.mirrors.refused == 1  # two slots
    assert not warehouse.mirror("base0", position=[5, 5, 0], **pose)  # this sim's own robot
    assert not warehouse.mirror("a", position=[math.nan, 0, 0], **pose)
    assert warehouse.unmirror("a") == ["a"] and warehouse.mirror(
        "c", position=[7, 5, 0], **pose
    )  # a freed slot is reused
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

        wait_until(
            lambda: put(2.0) or "base9" in mine.mirrors.held(),
            timeout=10,
            interval=0.05,
            what="base9 mirrored",
            seen=lambda: feed.counters,
        )
        wait_until(lambda: put(2.0) or ahead(mine) < free - 2.0, timeout=5, what="the LIDAR seeing base9 at 2 m")
        at2 = ahead(mine)
        wait_until(
            lambda: put(3.0) or abs(ahead(mine) - (at2 + 1.0)) < 0.02,
            timeout=5,
            what="the LIDAR seeing base9 move to 3 m",
            seen=lambda: ahead(mine),
        )
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
    with MirrorFeed(
        connect(kind="sim", peer_id="sim-a"),
        mine,
        threading.RLock(),
        describe=lambda: part,
        stale_s=2.0,
        clock=lambda: now[0],
    ) as feed:

        def put() -> None:
            other.publish(key, Pose(np.array([2.0, 0.0, 0.0]), np.array([1.0, 0, 0, 0]), header=other.header(key)))

        wait_until(lambda: put() or "base9" in mine.mirrors.held(), timeout=10, interval=0.05, what="base9 mirrored")
        assert feed.sweep() == []
        # no pose for longer than stale_s: hidden by the feed's own sweep, or by this one. The clock moves on at each
        # look: a pose of the loop above still on its way (at load) arrives after the first, and is stale by the next
        # (with the clock set once, a late pose kept base9 shown, and the test missed its deadline in a whole run)

        def silent_past_stale() -> bool:
            now[0] += 2.5
            return feed.sweep() is not None and "base9" not in mine.mirrors.held()

        wait_until(silent_past_stale, timeout=5, what="base9 hidden")
        assert feed.counters["hidden"] >= 1


def arm_elsewhere(q=None, at="1,0.5,30,0") -> tuple[SimWorld, RobotInfo]:
    """Another sim's arm (spawned on the floor, so a base's LIDAR plane crosses its links) at joints ``q``."""
    import mujoco

    other = SimWorld("warehouse", [f"meca500:arm9@{at}"], scene_robots=False)
    info = other.robot("arm9").describe()
    if q is not None:
        for name, v in zip(info.joint_names, q):
            j = mujoco.mj_name2id(other.model, mujoco.mjtObj.mjOBJ_JOINT, f"arm9/{name}")
            other.data.qpos[other.model.jnt_qposadr[j]] = v
        mujoco.mj_kinematics(other.model, other.data)
    return other, info


def test_an_arm_mirror_puts_each_link_where_the_arms_own_sim_has_it():
    import mujoco

    from sim_peer.physics.arm_mirror import arm_shape

    q = [0.4, -0.7, 0.9, 1.1, -0.5, 2.0]
    other, info = arm_elsewhere(q)
    shape = arm_shape(info)
    poses = shape.poses(q)
    names = [mujoco.mj_id2name(shape.model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in shape.geoms]
    assert len(poses) == len(shape.shapes) == 7, names  # the base and six links of the Meca500
    for name, (centre, quat) in zip(names, poses):
        g = mujoco.mj_name2id(other.model, mujoco.mjtObj.mjOBJ_GEOM, f"arm9/{name}")
        np.testing.assert_allclose(centre, other.data.geom_xpos[g], atol=1e-9, err_msg=name)
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, quat)
        np.testing.assert_allclose(mat, other.data.geom_xmat[g], atol=1e-9, err_msg=name)
    assert shape.poses(q[:5]) is None and shape.poses([math.nan] * 6) is None  # a malformed message moves nothing


def test_the_lidar_sees_a_mirrored_arm_and_sees_its_links_move():
    from sim_peer.physics.arm_mirror import arm_shape

    w = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=8)
    w.step(10)
    free = ahead(w)
    _, info = arm_elsewhere(at="1,0,0,0")  # 1 m ahead of base0, on the floor: the upper arm crosses the LIDAR plane
    shape = arm_shape(info)
    upright = [0.0] * 6
    assert w.mirror_shapes("arm9", shape.shapes, shape.poses(upright), source="sim-b")
    assert w.mirrors.free == 1  # seven of eight slots: one per link geom
    seen = ahead(w)
    assert seen == pytest.approx(1.0 - 0.22 - 0.032, abs=0.02)  # the upper arm's capsule, past the LIDAR's offset
    bowed = [0.0, 1.5, 0.0, 0.0, 0.0, 0.0]  # the shoulder bows the arm forward, under the LIDAR plane
    assert w.mirror_shapes("arm9", shape.shapes, shape.poses(bowed), source="sim-b")
    assert ahead(w) > seen + 0.5
    assert w.mirror("base8", radius=0.3, height=0.5, position=[5, 5, 0], quaternion=[1, 0, 0, 0])  # the last slot
    assert not w.mirror("base7", radius=0.3, height=0.5, position=[6, 5, 0], quaternion=[1, 0, 0, 0])
    assert w.unmirror(source="sim-b") == ["arm9"] and w.mirrors.free == 7
    assert ahead(w) == pytest.approx(free, abs=1e-6)


def test_the_feed_mirrors_another_sims_arm_from_its_joints(world, connect):
    """The arm's pose (its flange) makes the feed learn of it; its joints move its links; its sim's exit hides it."""
    mine = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=8)
    other = connect(kind="sim", peer_id="sim-b")
    _, info = arm_elsewhere(at="1,0,0,0")
    part = WorldInfo(world=world, scene="warehouse", timestep=mine.dt, rates={}, robots=(replace(info, sim="sim-b"),))
    pose_key, joints_key = keys.robot_pose(world, "arm9"), keys.robot_joints(world, "arm9")
    free = ahead(mine)
    lock = threading.RLock()  # the sim's step lock: the feed hides a mirror under it, in more than one statement
    with MirrorFeed(connect(kind="sim", peer_id="sim-a"), mine, lock, describe=lambda: part, stale_s=30.0) as feed:

        def put(q: list[float]) -> None:
            other.publish(
                pose_key, Pose(np.array([1.2, 0.0, 0.3]), np.array([1.0, 0, 0, 0]), header=other.header(pose_key))
            )
            other.publish(
                joints_key, JointState(info.joint_names, np.array(q), np.zeros(6), header=other.header(joints_key))
            )

        upright, bowed = [0.0] * 6, [0.0, 1.5, 0.0, 0.0, 0.0, 0.0]
        wait_until(
            lambda: put(upright) or "arm9" in mine.mirrors.held(),
            timeout=10,
            interval=0.05,
            what="arm9 mirrored",
            seen=lambda: feed.counters,
        )
        assert len(mine.mirrors.held()["arm9"].slots) == 7 and mine.mirrors.held()["arm9"].source == "sim-b"
        wait_until(
            lambda: put(upright) or ahead(mine) < 0.8,
            timeout=5,
            interval=0.05,
            what="the LIDAR seeing arm9's upper arm",
            seen=lambda: ahead(mine),
        )
        wait_until(
            lambda: put(bowed) or ahead(mine) > 1.5,
            timeout=5,
            interval=0.05,
            what="the LIDAR seeing arm9 bow under its plane",
            seen=lambda: ahead(mine),
        )
        assert feed.counters["joints"] >= 2 and feed.lag_ms
        other.close()

        def hidden() -> bool:  # read as the sim's sensors read: under its lock (a whole run once read a half-hidden
            with lock:  # mirror: gone from held(), its slots not yet free)
                return "arm9" not in mine.mirrors.held()

        wait_until(hidden, timeout=10, what="arm9's mirror hidden when sim-b left")
        with lock:
            assert ahead(mine) == pytest.approx(free, abs=1e-6) and mine.mirrors.free == 8


def test_a_robot_that_finds_too_few_slots_is_told_of_once(world, connect, caplog):
    """An arm needs 7 slots; a sim with 2 says so once, naming --mirrors, however many joint messages come."""
    import logging

    mine = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=2)
    other = connect(kind="sim", peer_id="sim-b")
    _, info = arm_elsewhere(at="1,0,0,0")
    part = WorldInfo(world=world, scene="warehouse", timestep=mine.dt, rates={}, robots=(replace(info, sim="sim-b"),))
    pose_key, joints_key = keys.robot_pose(world, "arm9"), keys.robot_joints(world, "arm9")
    with (
        caplog.at_level(logging.WARNING, logger="robofabric.sim"),
        MirrorFeed(
            connect(kind="sim", peer_id="sim-a"), mine, threading.RLock(), describe=lambda: part, stale_s=30.0
        ) as feed,
    ):

        def put() -> bool:
            other.publish(
                pose_key, Pose(np.array([1.2, 0.0, 0.3]), np.array([1.0, 0, 0, 0]), header=other.header(pose_key))
            )
            other.publish(
                joints_key, JointState(info.joint_names, np.zeros(6), np.zeros(6), header=other.header(joints_key))
            )
            return False

        wait_until(
            lambda: put() or feed.counters["joints"] >= 5,
            timeout=10,
            interval=0.05,
            what="five joint messages of arm9",
            seen=lambda: feed.counters,
        )
        assert feed.counters["unslotted"] == 1 and feed.counters["shown"] == 0 and not mine.mirrors.held()
        said = [r.getMessage() for r in caplog.records if "cannot mirror arm9" in r.getMessage()]
        assert len(said) == 1 and "needs 7 mirror slots and 2 of 2 are free" in said[0] and "--mirrors" in said[0], said
