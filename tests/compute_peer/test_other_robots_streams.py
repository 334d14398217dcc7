"""A world's robots of one kind on the keys another service hears: a base's wheel joints reach kinematics (they
are on ``robot/*/joints``), an arm's flange pose reaches navigation (``robot/*/pose``). Neither is an unknown
robot: each service passes them over quietly and counts ``unknown_robot`` only for an id no sim described
(every base's joints counted, 100 a second each: thousands a minute in a class of bases, issue 44)."""

from __future__ import annotations

import numpy as np

from compute_peer.kinematics.service import KinematicsService
from compute_peer.navigation import register_navigation
from fabric import keys
from fabric.interfaces import JointState, Pose, RobotInfo, Scan, WorldInfo
from robofabric.testing import wait_until

SIX = np.zeros(6)
BURST = 200


def _serve_world(sim, world: str) -> list[int]:
    """A sim describing one arm and one base; returns a list that grows by one per ``srv/world`` query."""
    robots = (
        RobotInfo("arm1", "meca500", "arm", np.zeros(4), tuple(f"j{i}" for i in range(6)), SIX - 3, SIX + 3, SIX + 1),
        RobotInfo("base1", "reeman", "mobile", np.zeros(4), ("left", "right"), np.zeros(2), np.zeros(2), np.zeros(2)),
    )
    asked: list[int] = []

    def answer(key: str, req: object) -> WorldInfo:
        asked.append(1)
        return WorldInfo(world, "test", 0.002, {}, robots)

    sim.rpc.serve(keys.srv(world, "world"), answer)
    return asked


def test_kinematics_passes_a_bases_wheel_joints_over_and_counts_an_undescribed_id(world, connect):
    sim = connect("sim")
    _serve_world(sim, world)
    svc = KinematicsService(connect("compute"), discover=True).start()
    try:
        wait_until(lambda: svc.arms == ["arm1"], timeout=20.0, what="the world answered")
        user = connect("user")
        wheels = JointState(("left", "right"), np.zeros(2), np.zeros(2))
        for _ in range(BURST):
            user.publish(keys.robot_joints(world, "base1"), wheels)
        ghosts = 0

        def counted() -> bool:  # a made-up id is counted once the world has answered since it appeared
            nonlocal ghosts
            if svc.counters.get("unknown_robot", 0) >= 1 and "arm1" in svc.joints:
                return True
            user.publish(keys.robot_joints(world, "ghost9"), wheels)
            user.publish(keys.robot_joints(world, "arm1"), JointState(tuple(f"j{i}" for i in range(6)), SIX, SIX))
            ghosts += 1
            return False

        wait_until(
            counted, timeout=20.0, interval=0.2, what="the arm's joints and the made-up id", seen=lambda: svc.counters
        )
        assert 1 <= svc.counters["unknown_robot"] <= ghosts, (ghosts, svc.counters)  # ghost9's only, never base1's
        assert set(svc.joints) == {"arm1"}
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
