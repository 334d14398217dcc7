"""A world's robots of one kind on the keys another service hears: a base's wheel joints on ``robot/*/joints``,
an arm's flange pose on ``robot/*/pose``. Once the sims have described the world, kinematics hears its arms' joints
alone and navigation its bases' poses alone, each on its own key: neither hears the other kind, nor a made-up id
(every base's joints were once counted unknown, 100 a second each: thousands a minute in a class of bases, issue 44;
then passed over, but still published by the sims for these services alone)."""

from __future__ import annotations

import numpy as np

from compute_peer.kinematics.service import KinematicsService
from compute_peer.navigation import register_navigation
from fabric import keys
from fabric.interfaces import JointState, Pose, RobotInfo, Scan, WorldInfo
from robofabric.testing import wait_until

SIX = np.zeros(6)
BURST = 200


def _serve_world(sim, world: str, arms: tuple[str, ...] = ("arm1",)) -> list[int]:
    """A sim describing its arms (``arms``: a list the test may grow) and one base; returns a list that grows by one
    per ``srv/world`` query."""
    base = RobotInfo("base1", "reeman", "mobile", np.zeros(4), ("left", "right"), np.zeros(2), np.zeros(2), np.zeros(2))
    asked: list[int] = []

    def answer(key: str, req: object) -> WorldInfo:
        asked.append(1)
        described = tuple(
            RobotInfo(a, "meca500", "arm", np.zeros(4), tuple(f"j{i}" for i in range(6)), SIX - 3, SIX + 3, SIX + 1)
            for a in arms
        )
        return WorldInfo(world, "test", 0.002, {}, (*described, base))

    sim.rpc.serve(keys.srv(world, "world"), answer)
    return asked


def _arm_joints() -> JointState:
    return JointState(tuple(f"j{i}" for i in range(6)), SIX, SIX)


def test_kinematics_hears_only_the_described_arms_joints(world, connect):
    """Once the sims have described the world, kinematics hears its arms' joints alone: a base's wheel joints (100
    Hz each) and a made-up id's never reach it (before, each was decoded and passed over, and the sims published
    every base's for this service alone)."""
    sim = connect("sim")
    _serve_world(sim, world)
    svc = KinematicsService(connect("compute"), discover=True).start()
    try:
        wait_until(
            lambda: svc.arms == ["arm1"] and svc.counters["joints_narrowed"] == 1,
            timeout=20.0,
            what="the world answered and kinematics narrowed",
            seen=lambda: (svc.arms, svc.counters),
        )
        user = connect("user")
        received = svc.fabric.counters["received"]
        wheels = JointState(("left", "right"), np.zeros(2), np.zeros(2))
        for _ in range(BURST):
            user.publish(keys.robot_joints(world, "base1"), wheels)
        user.publish(keys.robot_joints(world, "ghost9"), wheels)

        def heard() -> bool:  # published again each look: a route may come a moment after a session opens
            user.publish(keys.robot_joints(world, "arm1"), _arm_joints())
            return "arm1" in svc.joints

        wait_until(heard, timeout=20.0, interval=0.2, what="the arm's joints", seen=lambda: svc.counters)
        assert set(svc.joints) == {"arm1"}
        assert svc.counters.get("unknown_robot", 0) == 0, svc.counters  # ghost9's never came
        assert svc.fabric.counters["received"] - received < BURST, svc.fabric.counters  # no wheel joints came at all
    finally:
        svc.close()


def test_kinematics_hears_an_arm_a_later_lookup_names(world, connect):
    """A sim that comes later sets a lookup off; the arm it names is heard on its own key from then on."""
    arms = ["arm1"]
    sim = connect("sim")
    _serve_world(sim, world, arms)  # type: ignore[arg-type]
    svc = KinematicsService(connect("compute"), discover=True).start()
    try:
        wait_until(
            lambda: svc.counters["joints_narrowed"] == 1, timeout=20.0, what="narrowed", seen=lambda: svc.counters
        )
        arms.append("arm2")
        connect("sim")  # a second sim's token: the world's arms may have changed
        user = connect("user")

        def heard() -> bool:
            user.publish(keys.robot_joints(world, "arm2"), _arm_joints())
            return "arm2" in svc.joints

        wait_until(heard, timeout=20.0, interval=0.2, what="arm2's joints", seen=lambda: (svc.arms, svc.counters))
        assert svc.arms == ["arm1", "arm2"]
    finally:
        svc.close()


def test_navigation_hears_only_the_described_bases_poses_and_counts_an_undescribed_ids_scan(world, connect):
    """Once the sims have described the world, navigation hears the poses of its mobile robots alone: an arm's
    flange pose (100 Hz) and a made-up id's pose never reach it (before, each was decoded and passed over); a
    made-up id's scan, on ``robot/*/scan`` still, is counted ``unknown_robot``."""
    sim = connect("sim")
    _serve_world(sim, world)
    with register_navigation(connect("compute"), discover=True) as nav:
        wait_until(lambda: nav.discover_robots(1.0) == 1, timeout=20.0, what="the base learnt")
        assert nav.counters["poses_narrowed"] == 1
        user = connect("user")
        base1 = keys.robot_pose(world, "base1")
        received = nav.fabric.counters["received"]
        for _ in range(BURST):
            user.publish(keys.robot_pose(world, "arm1"), Pose([0.2, 0.0, 0.9]))
        user.publish(keys.robot_pose(world, "ghost9"), Pose([0.0, 0.0, 0.0]))

        def heard() -> bool:  # published again each look: a route may come a moment after a session opens
            user.publish(keys.robot_scan(world, "ghost9"), Scan(-1.0, 0.1, 5.0, np.full(21, 1000, np.uint16)))
            user.publish(base1, Pose([1.0, 0.0, 0.0]))
            return "base1" in nav.poses and nav.counters.get("unknown_robot", 0) >= 1

        wait_until(heard, timeout=20.0, what="the base's pose and the made-up id's scan", seen=lambda: nav.counters)
        assert "arm1" not in nav.poses and "ghost9" not in nav.poses, nav.poses.robots()
        assert nav.fabric.counters["received"] - received < BURST, nav.fabric.counters  # no arm pose came at all
