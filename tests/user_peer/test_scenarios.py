"""Test B end to end: `robofabric sim` as a process, the compute peer's navigation service, a scripted user.

`robofabric compute` does not exist yet, so the navigation service (compute_peer.navigation) is hosted
in-process on its own client session; Test A needs the compute peer's IK service and is exercised once
that lands (see docs/user_api.md).
"""

from __future__ import annotations

import uuid

from compute_peer.navigation.service import register_navigation
from fabric.session import Fabric
from fabric.testing import client, client_config, free_port, robofabric_cmd, router_config, wait_until
from user_peer.api import World
from user_peer.scenarios import SCENARIOS


def test_b_maps_plans_and_follows_to_the_goal(procs):
    world = f"t{uuid.uuid4().hex[:8]}"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    with Fabric(router_config(world, port), kind="router", peer_id="router") as router:
        sim = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
        wait_until(lambda: router.live_peers("sim"), timeout=90, what="sim peer", seen=lambda: procs.output(sim)[-1500:])
        with client(world, port, kind="compute", peer_id="nav") as comp:
            nav = register_navigation(comp)
            with World(client_config(world, port), "bob", timeout=10.0) as w:
                res = SCENARIOS["test-b"](w, arm_id=None)
            nav.close()
    assert res.ok, "\n".join(res.lines)
    assert res.figures["goal_error_m"] <= 0.3
    assert any("map built" in line for line in res.lines) and any(line.startswith("planned") for line in res.lines)
