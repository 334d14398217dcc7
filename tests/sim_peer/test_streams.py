"""A sim's stream groups: each on its own rate loop, the loops' grids staggered from one origin."""

from __future__ import annotations

import threading
from collections import Counter

import pytest

from fabric import keys
from robofabric.testing import wait_until
from sim_peer.streams import StreamLoops
from sim_peer.world import SimWorld


def test_the_default_groups_tick_a_third_of_the_joints_period_apart(router):
    """Joints (100 Hz), poses (50 Hz) and scans (20 Hz) start 0, 1/300 and 2/300 s after one origin: every pose or
    scan tick falls between two joints ticks, so a subscriber of all three never gets two bursts at once."""
    fab, _ = router
    loops = StreamLoops(fab, SimWorld("combined", seed=3), threading.RLock(), Counter())
    assert set(loops.groups) == {"joints", "pose", "scan"}
    assert loops.offsets() == pytest.approx({"joints": 0.0, "pose": 1 / 300, "scan": 2 / 300})


def test_the_offsets_follow_the_rates_given(router):
    """Rates given at start reorder the groups: the fastest starts at the origin, the others after it."""
    fab, _ = router
    loops = StreamLoops(fab, SimWorld("combined", seed=3), threading.RLock(), Counter(),
                        rates={"joints": 25.0, "pose": 200.0, "scan": 50.0})
    assert loops.offsets() == pytest.approx({"pose": 0.0, "scan": 1 / 600, "joints": 2 / 600})


@pytest.mark.slow
def test_staggered_loops_publish_every_group(world, router, connect):
    """Started, the loops share one origin, each group's grid at its offset from it, and every group publishes."""
    fab, _ = router
    sim_fab = connect("sim", "sim-streams")
    loops = StreamLoops(sim_fab, SimWorld("combined", seed=3), threading.RLock(), Counter())
    got: Counter[str] = Counter()
    for stream in ("joints", "pose", "scan"):
        fab.subscribe(keys.robot_stream_all(world, stream), lambda key, msg: got.update([key.rsplit("/", 1)[1]]))
    loops.start()
    try:
        origin = loops.loops["joints"].start_at
        assert {g: loop.start_at - origin for g, loop in loops.loops.items()} == pytest.approx(loops.offsets())
        wait_until(lambda: all(got[s] >= 3 for s in ("joints", "pose", "scan")), timeout=30,
                   what="every group's stream", seen=lambda: dict(got))
    finally:
        loops.stop()
