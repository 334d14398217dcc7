"""A standby's take-over reaches a script as what it is: "sim sim-a failed over to sim-b", through
``World.on_failover`` and ``World.failovers``, after the robots' loss (``on_robots_gone``), not
only as "robots ... gone from world". And a world that was there from the start is never "back"."""

from __future__ import annotations

import logging

import pytest

from robofabric.testing import SimRoles, client, client_config, robofabric_cmd, wait_until
from user_peer.api import World

pytestmark = pytest.mark.slow  # a primary sim and its standby


def test_a_standby_taking_over_is_told_as_a_failover(world, router, procs, caplog):
    ep = f"tcp/127.0.0.1:{router[1]}"
    common = ("--scene", "combined", "--world", world, "--connect", ep)
    primary = procs.start(robofabric_cmd("sim", *common, "--id", "sim-a"), name="sim-a")
    standby = procs.start(robofabric_cmd("sim", *common, "--id", "sim-b", "--standby"), name="sim-b")
    with client(world, router[1], peer_id="roles") as fab:
        SimRoles(fab).wait(
            "sim-b",
            "standby",
            term=1,
            leader="sim-a",
            timeout=90,
            seen=lambda: (procs.output(primary)[-1000:], procs.output(standby)[-1000:]),
        )
    caplog.set_level(logging.INFO, logger="robofabric.user")
    w = World(client_config(world, router[1]), "alice", timeout=10.0)
    try:
        told: list[tuple[str, str, list[str]]] = []
        whys: list[str] = []
        w.on_failover(lambda sim, to, robots: told.append((sim, to, robots)))
        w.on_world(lambda alive, why: whys.append(why))
        wait_until(lambda: sorted(w.robots()) == ["arm1", "base1"], timeout=30, what="the world's robots")
        assert not any("is back" in r.getMessage() for r in caplog.records), [r.getMessage() for r in caplog.records]
        procs.kill(primary)  # SIGKILL, by pid
        wait_until(
            lambda: told,
            timeout=40,
            what="the failover told",
            seen=lambda: (w.robots_gone, procs.output(standby)[-800:]),
        )
        assert told == [("sim-a", "sim-b", ["arm1", "base1"])] and w.failovers == told
        assert sorted(w.robots_gone) == ["arm1", "base1"]  # told first, as before
        said = [r.getMessage() for r in caplog.records]
        assert any("sim sim-a failed over to sim-b" in m for m in said), said
        assert not any("is back" in m for m in said) and not [y for y in whys if "serves" not in y], (
            said,
            whys,
        )  # the world never went (its first sim's "serves" may come after on_world was set)
    finally:
        w.close()
