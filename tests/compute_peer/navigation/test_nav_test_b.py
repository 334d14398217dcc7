"""The paper's Test B with the real sim peer: drive to map, build the map, plan to the goal, follow the path.

A MuJoCo sim peer serves the warehouse (10 m hall, four shelves, a pillar) with its Reeman-like robot; the
navigation service learns the LIDAR's mounting and the robot's radius from the sim's world description, maps
while the robot turns on the spot, builds the map, plans to the goal pointer through the gap between two
shelves, and the robot, sent the path as a command, drives it to the goal.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from compute_peer.navigation import path_collision, register_navigation
from fabric.interfaces import (
    Command,
    MapRequest,
    PlanRequest,
    Pose,
    Stop,
    Twist,
    quaternion_from_yaw,
    yaw_from_quaternion,
)
from fabric import keys
from robofabric.testing import wait_until
from sim_peer.serving.peer import SimPeer
from sim_peer.physics.world import SimWorld

pytestmark = pytest.mark.slow

ROBOT = "base1"


def test_drive_map_plan_and_follow(world, connect):
    sim_fab = connect("sim", "sim-b")
    sim = SimPeer(sim_fab, SimWorld("warehouse", seed=1), rates={"joints": 10, "pose": 50, "scan": 20}, speed=3.0)
    sim.start()
    try:
        compute = connect("compute", "compute-b")
        user = connect("user", "alice")
        poses: list[Pose] = []
        user.subscribe(keys.robot_pose(world, ROBOT), lambda k, m: poses.append(m), expected=Pose)
        with register_navigation(compute) as nav:
            wait_until(lambda: nav.discover_robots(timeout=1.0) >= 1, what="the sim's world description")
            assert nav.descriptions.learnt_offset(ROBOT)[0] == pytest.approx(
                0.22
            )  # the LIDAR is 22 cm ahead of the axle
            # mapping mode: the user turns the robot on the spot, a little more than once around
            wait_until(lambda: poses, what="robot pose")
            turned = [0.0]

            def turning() -> bool:
                user.publish(keys.robot_cmd(world, ROBOT, "twist", "alice"), Command("alice", 1, Twist(0.0, 1.2)))
                yaws = np.unwrap([yaw_from_quaternion(p.quaternion) for p in poses[-400:]])
                turned[0] = abs(yaws[-1] - yaws[0]) if len(yaws) > 1 else 0.0
                return nav.counters["scans"] >= 40 and turned[0] > 2 * math.pi + 0.5

            wait_until(
                turning, timeout=30.0, interval=0.1, what="a full turn of scans", seen=lambda: (nav.counters, turned)
            )
            user.publish(keys.robot_cmd(world, ROBOT, "stop", "alice"), Command("alice", 1, Stop()))
            built = user.rpc.call(keys.srv(world, "map", "map"), MapRequest("build"), timeout=10.0).grid
            # the hall's walls and the shelves facing the robot are in the map where MuJoCo has them
            cells = built.cells

            def near(x, y, k=2):
                """The cells within k of the one holding (x, y)."""
                r = int((y - built.origin[1]) / built.resolution)
                c = int((x - built.origin[0]) / built.resolution)
                return cells[r - k : r + k + 1, c - k : c + k + 1]

            for face in (
                (0.0, 5.0),
                (5.0, 0.0),
                (-5.0, 0.0),
                (2.5, 2.2),
                (-2.5, 2.2),
                (0.0, -1.3),
            ):  # walls, shelves, pillar
                assert (near(*face) == 100).any(), face
            for floor in ((0.0, 4.0), (1.5, 0.5), (-3.0, 0.0), (0.0, 0.0)):  # the aisle, open floor, under the robot
                assert (near(*floor) == 0).all(), floor
            assert (cells == 100).sum() > 300

            # navigation mode: the goal pointer is moved to the aisle behind the shelves' gap
            goal = (0.0, 4.0, math.pi / 2)
            user.publish(
                keys.object_pose(world, "goal", "alice"),
                Pose(np.array([goal[0], goal[1], 0.0]), quaternion_from_yaw(goal[2])),
            )
            wait_until(lambda: nav.plan_service.goal is not None, what="goal pointer")
            reply = user.rpc.call(keys.srv(world, "plan", ROBOT), PlanRequest(ROBOT), timeout=20.0)
            path = reply.path
            assert (path.x[-1], path.y[-1]) == pytest.approx(goal[:2])
            assert (
                path_collision(nav.plan_service.costmap("map", 0.30), path.x, path.y) is None
            )  # radius from the description
            # the user decides to follow it: the path as a command, and the robot drives it
            user.publish(keys.robot_cmd(world, ROBOT, "path", "alice"), Command("alice", 1, path))

            def arrived() -> bool:
                p = poses[-1].position
                return math.hypot(p[0] - goal[0], p[1] - goal[1]) < 0.15

            wait_until(arrived, timeout=30.0, interval=0.05, what="robot at the goal", seen=lambda: poses[-1].position)
    finally:
        sim.close()
