"""Test B in a crowded class, with the real sim peer: two bases see each other, and neither is a wall in a map.

The issue's scene (issue 44): base1 at the warehouse's centre, base2 parked at (-2, 1.5) facing it. Both LIDARs
scan; base2's sees base1 all the time. bob turns base1 on the spot to map, builds his own map, plans to the aisle
behind the shelves' gap and follows: before maps left robots out, base2's scans had mapped base1 as a wall around
its own start and every plan was refused ("start ... is within the robot radius of an obstacle").
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from compute_peer.navigation import register_navigation
from compute_peer.navigation.robot_cells import Footprint, robot_cells
from fabric import keys
from fabric.interfaces import (
    Command,
    MapRequest,
    PlanRequest,
    Pose,
    Scan,
    Stop,
    Twist,
    quaternion_from_yaw,
    yaw_from_quaternion,
)
from robofabric.testing import wait_until
from robots import SceneRobot
from sim_peer.serving.peer import SimPeer
from sim_peer.physics.world import SimWorld

pytestmark = pytest.mark.slow

PARKED = (-2.0, 1.5)
FACING = math.atan2(0.0 - PARKED[1], 0.0 - PARKED[0])  # base2 looks at base1, at the origin
RADIUS = 0.30  # the Reeman's, from its description
LIDAR_AHEAD = 0.22


def _hits_on(scan: Scan, x: float, y: float, yaw: float, target: tuple[float, float], within: float) -> int:
    """How many of ``scan``'s end points (taken by a base at (x, y, yaw)) lie within ``within`` of ``target``."""
    sx, sy = x + LIDAR_AHEAD * math.cos(yaw), y + LIDAR_AHEAD * math.sin(yaw)
    r = np.asarray(scan.ranges, dtype=float)
    hit = r < scan.range_max - 1e-6
    ex, ey = sx + r * np.cos(scan.angles + yaw), sy + r * np.sin(scan.angles + yaw)
    return int((np.hypot(ex - target[0], ey - target[1])[hit] <= within).sum())


def test_a_map_built_beside_a_parked_base_holds_none_of_it_and_the_plan_is_followed(world, connect):
    sim_fab = connect("sim", "sim-b")
    parked = SceneRobot("reeman", "base2", (PARKED[0], PARKED[1], 0.0, FACING))
    sim = SimPeer(
        sim_fab, SimWorld("warehouse", [parked], seed=1), rates={"joints": 10, "pose": 50, "scan": 20}, speed=3.0
    )
    sim.start()
    try:
        compute = connect("compute", "compute-b")
        bob = connect("user", "bob")
        poses: list[Pose] = []
        seen_base1 = [0]  # base2's rays that ended on base1: the scene is the issue's only while this grows
        bob.subscribe(keys.robot_pose(world, "base1"), lambda k, m: poses.append(m), expected=Pose)

        def on_base2_scan(key: str, scan: Scan) -> None:
            p = poses[-1].position if poses else (0.0, 0.0)
            seen_base1[0] += _hits_on(scan, PARKED[0], PARKED[1], FACING, (float(p[0]), float(p[1])), RADIUS + 0.05)

        bob.subscribe(keys.robot_scan(world, "base2"), on_base2_scan, expected=Scan)
        with register_navigation(compute) as nav:  # every robot of the world: both bases map
            wait_until(lambda: nav.discover_robots(timeout=1.0) >= 2, what="the sim's world description")
            wait_until(lambda: poses and "base2" in nav.poses, what="both bases' poses")
            turned = [0.0]

            def turning() -> bool:  # bob turns base1 on the spot, a little more than once around
                bob.publish(keys.robot_cmd(world, "base1", "twist", "bob"), Command("bob", 1, Twist(0.0, 1.2)))
                yaws = np.unwrap([yaw_from_quaternion(p.quaternion) for p in poses[-400:]])
                turned[0] = abs(yaws[-1] - yaws[0]) if len(yaws) > 1 else 0.0
                return nav.counters["scans"] >= 80 and turned[0] > 2 * math.pi + 0.5

            wait_until(
                turning, timeout=30.0, interval=0.1, what="a full turn of scans", seen=lambda: (nav.counters, turned)
            )
            bob.publish(keys.robot_cmd(world, "base1", "stop", "bob"), Command("bob", 1, Stop()))
            assert seen_base1[0] > 50  # base2 saw base1 all along

            reply = bob.rpc.call(keys.srv_asked(world, "map", "map", "bob"), MapRequest("build"), timeout=10.0)
            assert reply.name == "bob.map"
            here = poses[-1].position
            robots = [Footprint(float(here[0]), float(here[1]), RADIUS), Footprint(PARKED[0], PARKED[1], RADIUS)]
            for robot in robots:
                assert robot_cells(reply.grid, [robot]) == 0, robot  # neither base is a wall in bob's map
            assert (reply.grid.cells == 100).sum() > 300  # the hall is

            goal = (0.0, 4.0, math.pi / 2)  # the aisle behind the shelves' gap
            bob.publish(
                keys.object_pose(world, "goal", "bob"),
                Pose(np.array([goal[0], goal[1], 0.0]), quaternion_from_yaw(goal[2])),
            )
            wait_until(lambda: nav.plan_service.goal is not None, what="goal pointer")
            plan = bob.rpc.call(
                keys.srv_asked(world, "plan", "base1", "bob"), PlanRequest("base1", map="bob.map"), timeout=20.0
            )
            assert (plan.path.x[-1], plan.path.y[-1]) == pytest.approx(goal[:2])
            bob.publish(keys.robot_cmd(world, "base1", "path", "bob"), Command("bob", 1, plan.path))

            def arrived() -> bool:
                p = poses[-1].position
                return math.hypot(p[0] - goal[0], p[1] - goal[1]) < 0.1

            wait_until(arrived, timeout=30.0, interval=0.05, what="base1 at the goal", seen=lambda: poses[-1].position)
            # the class's map, built from the same scans, holds neither base either
            built = bob.rpc.call(keys.srv(world, "map", "map"), MapRequest("build"), timeout=10.0).grid
            assert robot_cells(built, [Footprint(PARKED[0], PARKED[1], RADIUS)]) == 0
    finally:
        sim.close()
