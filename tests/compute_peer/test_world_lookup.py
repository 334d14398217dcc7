"""The compute services' one way of looking the world up: one run at a time, at most once per interval."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from compute_peer.world_lookup import BackgroundLookup, described_robots
from fabric import keys
from fabric.interfaces import NoReply, RobotInfo, WorldInfo
from fabric.rate import FakeClock
from robofabric.testing import client, wait_until


def test_one_run_per_interval_and_none_after_close():
    clock = FakeClock()
    runs: list[float] = []
    lookup = BackgroundLookup(runs.append, name="t", on_error=lambda exc: None, clock=clock)
    assert lookup.claim(1.0)
    assert not lookup.claim(1.0)  # one at a time
    lookup.run(0.5)
    assert runs == [0.5] and lookup.ended == clock.now()
    assert not lookup.claim(1.0)  # too soon
    clock.jump(1.0)
    assert lookup.claim(1.0)
    lookup.run(0.5)
    lookup.again_now()
    lookup.close()
    assert not lookup.claim(1.0)


def test_a_failing_run_is_reported_and_the_next_may_start():
    clock = FakeClock()
    seen: list[Exception] = []

    def fail(timeout: float) -> None:
        raise RuntimeError("session closed")

    lookup = BackgroundLookup(fail, name="t", on_error=seen.append, clock=clock)
    assert lookup.claim(0.0)
    lookup.run(0.1)
    assert [str(e) for e in seen] == ["session closed"]
    assert not lookup.running and lookup.claim(0.0)


def test_start_runs_on_a_thread_and_wait_joins_it():
    gate = threading.Event()
    lookup = BackgroundLookup(lambda timeout: gate.wait(5), name="t", on_error=lambda exc: None)
    assert lookup.start(0.0)
    assert lookup.running and not lookup.start(0.0)
    gate.set()
    assert lookup.wait(5) and not lookup.running


def _robot(rid: str, kind: str) -> RobotInfo:
    return RobotInfo(rid, "t", kind, np.zeros(4), (), np.zeros(0), np.zeros(0), np.zeros(0))


def test_described_robots_are_the_sims_robots_of_one_kind(router, world):
    _, port = router
    with client(world, port, kind="sim", peer_id="sim1") as sim, client(world, port, peer_id="c1") as compute:
        with pytest.raises(NoReply):
            described_robots(compute, "arm", timeout=0.5)
        robots = (_robot("arm1", "arm"), _robot("base1", "mobile"))
        sim.rpc.serve(keys.srv(world, "world"), lambda key, req: WorldInfo(world, "s", 0.002, {}, robots))
        wait_until(lambda: _answers(compute), what="the new queryable known through the router")
        assert [r.id for r in described_robots(compute, "mobile")] == ["base1"]
        assert [r.id for r in described_robots(compute, "arm")] == ["arm1"]


def _answers(compute) -> bool:
    try:
        described_robots(compute, "arm", timeout=0.5)
        return True
    except NoReply:
        return False
