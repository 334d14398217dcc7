"""The paper's Test A and Test B with the arm and the base on different sims of one world (docs/sim.md)."""

from __future__ import annotations

import pytest

from robofabric.testing import client_config, robofabric_cmd, wait_until
from user_peer.api import World
from tests.user_peer.test_scenarios import assert_b_then_a
from user_peer.scenarios import SCENARIOS

pytestmark = pytest.mark.slow


def test_b_then_a_with_the_arm_on_one_sim_and_the_base_on_another(world, router, procs):
    ep = f"tcp/127.0.0.1:{router[1]}"
    fab, port = router
    common = ("--scene", "combined", "--no-scene-robots", "--world", world, "--connect", ep)
    arm_sim = procs.start(
        robofabric_cmd("sim", *common, "--robot", "meca500:arm1@3,0,0,0.75", "--id", "sim-arm"), name="sim-arm"
    )
    wait_until(
        lambda: ("sim", "sim-arm") in fab.live_peers("sim"),
        timeout=90,
        what="the arm's sim",
        seen=lambda: procs.output(arm_sim)[-1500:],
    )
    base_sim = procs.start(
        robofabric_cmd("sim", *common, "--robot", "reeman:base1@0,0", "--id", "sim-base"), name="sim-base"
    )
    wait_until(
        lambda: "as a shard beside sim-arm" in procs.output(base_sim),
        timeout=90,
        what="the base's sim joining as a shard",
        seen=lambda: procs.output(base_sim)[-1500:],
    )
    comp = procs.start(robofabric_cmd("compute", "--world", world, "--connect", ep), name="compute")
    wait_until(
        lambda: "arms arm1" in procs.output(comp),
        timeout=90,
        what="compute peer serving arm1",
        seen=lambda: procs.output(comp)[-1500:],
    )
    with World(client_config(world, port), "bob", timeout=10.0) as w:
        assert {r.id: r.sim for r in w.info().robots} == {"arm1": "sim-arm", "base1": "sim-base"}
        res_b = SCENARIOS["test-b"](w, arm_id="arm1")
    with World(client_config(world, port), "alice", timeout=10.0) as w:
        res_a = SCENARIOS["test-a"](w, arm_id="arm1", points=4)
    assert_b_then_a(res_b, res_a)
