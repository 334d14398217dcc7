"""Sensors see across sims: base0's LIDAR, simulated by sim-a, sees base1, simulated by sim-b, and sees it move.

Each sim mirrors the other sims' robots as kinematic bodies from their pose and joint streams
(sim_peer/physics/mirrors.py, sim_peer/shards/mirroring.py); when sim-b goes, sim-a's mirror of base1 goes with it."""

from __future__ import annotations

import numpy as np
import pytest

from robofabric.testing import client_config, robofabric_cmd, wait_until
from user_peer.api import World

pytestmark = pytest.mark.slow

FORWARD = slice(118, 123)  # the rays straight ahead of a base at yaw 0 (240 rays over the LIDAR's field of view)
FREE_AHEAD = 4.5  # the warehouse has nothing closer than this ahead of (0, 0) along +x (no other robot)


def _ahead(w: World) -> float:
    scan = w.robot("base0").scan
    return float(np.median(scan.ranges[FORWARD])) if scan is not None else float("nan")


SCENE = ("--scene", "warehouse", "--no-scene-robots")


def _sim_a(world, router, connect, procs):
    """sim-a, serving base0 at the origin facing +x, logging what it mirrors; (common CLI args, probe, sim-a)."""
    common = ("--world", world, "--connect", f"tcp/127.0.0.1:{router[1]}")
    sim_a = procs.start(
        robofabric_cmd("-v", "sim", *SCENE, "--robot", "reeman:base0@0,0", *common, "--id", "sim-a"), name="sim-a"
    )
    probe = connect("tool", "probe")
    wait_until(
        lambda: ("sim", "sim-a") in probe.live_peers("sim"),
        timeout=60,
        what="sim-a",
        seen=lambda: procs.output(sim_a)[-800:],
    )
    return common, probe, sim_a


def test_a_lidar_sees_a_robot_another_sim_simulates_and_sees_it_move(world, router, connect, procs):
    common, probe, sim_a = _sim_a(world, router, connect, procs)
    w = World(client_config(world, router[1]), "alice", timeout=10.0)
    try:
        w.robot("base0").wait_for("scan", timeout=30)
        alone = wait_until(
            lambda: _ahead(w) > FREE_AHEAD and _ahead(w),
            timeout=20,
            what="a clear view ahead of base0",
            seen=lambda: _ahead(w),
        )
        sim_b = procs.start(
            robofabric_cmd("sim", *SCENE, "--robot", "reeman:base1@3,0,180", *common, "--id", "sim-b"), name="sim-b"
        )
        # sim-a mirrors base1 from sim-b's poses: base0's LIDAR sees its shell, 3 m ahead less radius and LIDAR offset
        seen = wait_until(
            lambda: 2.0 < _ahead(w) < 2.9 and _ahead(w),
            timeout=60,
            what="base0's LIDAR seeing base1 (sim-b)",
            seen=lambda: (_ahead(w), procs.output(sim_a)[-600:], procs.output(sim_b)[-600:]),
        )
        w.info(refresh=True)
        base1 = w.robot("base1")
        base1.wait_for("pose", timeout=20)
        base1.request(timeout=10)
        x_before = base1.xy_theta[0]
        base1.drive(-0.3, 0.0, 1.5)  # base1 faces -x: backing up takes it away from base0
        assert base1.stop(timeout=10)
        moved = base1.xy_theta[0] - x_before
        assert moved > 0.2, moved
        # base0's LIDAR sees it where sim-b says it is: the reading grew by what base1 moved (noise, and a pose period)
        wait_until(
            lambda: abs((_ahead(w) - seen) - moved) < 0.08,
            timeout=10,
            what="base0's LIDAR seeing base1 back away",
            seen=lambda: (_ahead(w), seen, moved),
        )
        procs.kill(sim_b)  # sim-b goes: its token with it, and sim-a's mirror of base1
        wait_until(
            lambda: _ahead(w) > FREE_AHEAD,
            timeout=30,
            what="base1's mirror gone with sim-b",
            seen=lambda: (_ahead(w), alone),
        )
        assert "mirroring base1 (simulated by sim-b)" in procs.output(sim_a)
    finally:
        w.close()


def test_a_lidar_sees_the_links_of_an_arm_another_sim_simulates(world, router, connect, procs):
    """An arm on the floor 1 m ahead of base0, on sim-b: sim-a mirrors its links from its joint stream, so base0's
    LIDAR sees its upper arm, then sees it bow under the LIDAR plane when its owner moves it."""
    common, probe, sim_a = _sim_a(world, router, connect, procs)
    sim_b = procs.start(
        robofabric_cmd("sim", *SCENE, "--robot", "meca500:arm1@1,0,0,0", *common, "--id", "sim-b"), name="sim-b"
    )
    wait_until(
        lambda: ("sim", "sim-b") in probe.live_peers("sim"),
        timeout=60,
        what="sim-b",
        seen=lambda: procs.output(sim_b)[-800:],
    )
    w = World(client_config(world, router[1]), "alice", timeout=10.0)
    try:
        w.robot("base0").wait_for("scan", timeout=30)
        # the upper arm's capsule, 1 m ahead less the LIDAR's offset (0.22 m) and the capsule's radius
        wait_until(
            lambda: 0.65 < _ahead(w) < 0.85,
            timeout=60,
            what="base0's LIDAR seeing arm1's links (sim-b)",
            seen=lambda: (_ahead(w), procs.output(sim_a)[-600:], procs.output(sim_b)[-600:]),
        )
        arm = w.robot("arm1")
        arm.request(timeout=10)
        arm.move_joints([0.0, 1.5, 0.0, 0.0, 0.0, 0.0], wait=True, timeout=30)  # bowed forward, under the LIDAR plane
        wait_until(
            lambda: _ahead(w) > 1.5,
            timeout=10,
            what="base0's LIDAR no longer seeing arm1's upper arm",
            seen=lambda: (_ahead(w), arm.joints),
        )
        assert "mirroring arm1 (simulated by sim-b; 7 link geoms)" in procs.output(sim_a)
        procs.kill(sim_b)
        wait_until(
            lambda: "no longer mirroring arm1" in procs.output(sim_a),
            timeout=30,
            what="arm1's mirror gone with sim-b",
            seen=lambda: procs.output(sim_a)[-600:],
        )
    finally:
        w.close()
