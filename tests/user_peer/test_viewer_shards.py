"""The viewer in a world of several sims: a sim that joins later (a shard) has its robots described too."""

from __future__ import annotations

import threading
from dataclasses import replace

from fabric import keys
from fabric.interfaces import OwnershipRecord, WorldInfo
from robofabric.testing import client_config, wait_until
from sim_peer.physics.world import SimWorld
from user_peer.viewer import Viewer, ViewerOptions


def _part(world: str, sim: str, robot: str) -> WorldInfo:
    w = SimWorld("warehouse", [f"reeman:{robot}@{1.5 if robot == 'base1' else 0},0"], scene_robots=False)
    return WorldInfo(
        world=world, scene="warehouse", timestep=w.dt, rates={}, robots=(replace(w.robot(robot).describe(), sim=sim),)
    )


def test_a_shard_joining_later_has_its_robots_in_the_viewers_world(world, router, connect, tmp_path):
    sim_a = connect("sim", "sim-a")
    sim_a.rpc.serve(keys.srv(world, "world"), lambda key, req: _part(world, "sim-a", "base0"))
    viewer = Viewer(
        client_config(world, router[1]), ViewerOptions(save=tmp_path / "v.rrd", max_hz=0), peer_id="viewer-shards"
    )
    stop = threading.Event()
    t = threading.Thread(target=viewer.run, args=(stop,), daemon=True)
    t.start()
    try:
        wait_until(
            lambda: viewer.catalog.world_info is not None, timeout=20, what="the viewer's first look at the world"
        )
        assert [r.id for r in viewer.catalog.world_info.robots] == ["base0"]
        sim_b = connect("sim", "sim-b")  # its token: a sim joining the world, serving its own part
        # base1's record is served, never published (it went out before the viewer's subscription reached sim-b)
        rec_key = keys.own(world, "base1")
        sim_b.rpc.serve(
            rec_key,
            lambda key, req: OwnershipRecord(
                "base1", owner="bob", epoch=3, authority="sim-b", header=sim_b.header(rec_key)
            ),
        )
        sim_b.rpc.serve(keys.srv(world, "world"), lambda key, req: _part(world, "sim-b", "base1"))
        wait_until(
            lambda: {r.id: r.sim for r in viewer.catalog.world_info.robots} == {"base0": "sim-a", "base1": "sim-b"},
            timeout=20,
            what="both sims' robots in the viewer's world",
            seen=lambda: [(r.id, r.sim) for r in viewer.catalog.world_info.robots],
        )
        wait_until(
            lambda: "base1" in viewer.logger.owners,
            timeout=20,
            what="base1's record, asked when sim-b joined",
            seen=lambda: viewer.logger.owners,
        )
        assert viewer.logger.owners["base1"].owner == "bob"
    finally:
        stop.set()
        t.join(timeout=20)


def test_a_viewer_started_before_its_sim_learns_the_world_when_the_sim_comes(world, router, connect, tmp_path):
    """Its look at the start finds no sim: the first sim's token makes it ask again (before, it never did, and a
    loaded lab's viewer drew nothing for its whole run)."""
    viewer = Viewer(
        client_config(world, router[1]), ViewerOptions(save=tmp_path / "v.rrd", max_hz=0), peer_id="viewer-early"
    )
    try:
        viewer.start()
        assert viewer.catalog.world_info is None  # nobody served the world at its start
        sim_a = connect("sim", "sim-a")
        sim_a.rpc.serve(keys.srv(world, "world"), lambda key, req: _part(world, "sim-a", "base0"))
        wait_until(
            lambda: (
                viewer.catalog.world_info is not None and [r.id for r in viewer.catalog.world_info.robots] == ["base0"]
            ),
            timeout=30,
            what="the world learnt from the sim that came",
            seen=lambda: viewer.catalog.world_info,
        )
    finally:
        viewer.close()
