"""A sim's stream groups: each on its own rate loop, the loops' grids staggered from one origin."""

from __future__ import annotations

import threading
from collections import Counter

import pytest

from fabric import keys
from robofabric.testing import wait_until
from robofabric.bench.shards import spots
from sim_peer.serving.streams import StreamLoops, _dealt
from sim_peer.physics.world import SimWorld


def test_the_default_groups_tick_a_third_of_the_joints_period_apart(router):
    """Joints (100 Hz), poses (50 Hz) and scans (20 Hz) start 0, 1/300 and 2/300 s after one origin: every pose or
    scan tick falls between two joints ticks, so a subscriber of all three never gets two bursts at once."""
    fab, _ = router
    loops = StreamLoops(fab, SimWorld("combined", seed=3), threading.RLock(), Counter())
    assert set(loops.groups) == {"joints", "pose", "scan"}
    assert loops.offsets() == pytest.approx({"joints": 0.0, "pose": 1 / 300, "scan": 2 / 300})


def test_the_offsets_follow_the_rates_given(router):
    """Rates given at start reorder the groups: the fastest starts at the origin, the others after it, by how
    often their loops tick (joints at 25 Hz for 2 robots: 2 phases, a 50 Hz loop, like the scans')."""
    fab, _ = router
    loops = StreamLoops(
        fab,
        SimWorld("combined", seed=3),
        threading.RLock(),
        Counter(),
        rates={"joints": 25.0, "pose": 200.0, "scan": 50.0},
    )
    assert loops.phases == {"joints": 2, "pose": 1, "scan": 1}
    assert loops.offsets() == pytest.approx({"pose": 0.0, "joints": 1 / 600, "scan": 2 / 600})


def test_a_class_of_bases_sends_its_scans_a_few_robots_a_tick(router):
    """8 bases: the 20 Hz scans (and sonars) are dealt over 5 phases of a 100 Hz loop, the 50 Hz poses over 2;
    each robot is in one phase, with all its streams of the group, and keeps its rate."""
    fab, _ = router
    world = SimWorld("warehouse", spots(8), scene_robots=False, seed=3)
    loops = StreamLoops(fab, world, threading.RLock(), Counter())
    assert loops.phases == {"joints": 1, "pose": 2, "scan": 5}
    assert {g: loops.loop_rate(g) for g in loops.groups} == {"joints": 100.0, "pose": 100.0, "scan": 100.0}
    dealt = _dealt(loops.groups["scan"], loops.phases["scan"])
    robots = [sorted({key.split("/")[3] for key, _ in phase}) for phase in dealt]
    assert robots == [["base0", "base5"], ["base1", "base6"], ["base2", "base7"], ["base3"], ["base4"]]
    streams = [sorted(key.rsplit("/", 1)[1] for key, _ in phase) for phase in dealt]
    assert streams[3] == ["scan", "sonar"]  # a base's LIDAR and sonar ring go out in the same tick
    assert sorted(k for phase in dealt for k, _ in phase) == sorted(k for k, _ in loops.groups["scan"])


@pytest.mark.slow
def test_staggered_loops_publish_every_group(world, router, connect):
    """Started, the loops share one origin, each group's grid at its offset from it, and every robot's stream
    of every group is published, whatever phase its robot was dealt."""
    fab, _ = router
    sim_fab = connect("sim", "sim-streams")
    loops = StreamLoops(
        sim_fab, SimWorld("warehouse", spots(3), scene_robots=False, seed=3), threading.RLock(), Counter()
    )
    got: Counter[str] = Counter()
    for stream in ("joints", "pose", "scan"):
        fab.subscribe(keys.robot_stream_all(world, stream), lambda key, msg: got.update(["/".join(key.split("/")[3:])]))
    expected = [
        key.split("/", 3)[3]
        for entries in loops.groups.values()
        for key, _ in entries
        if key.rsplit("/", 1)[1] in ("joints", "pose", "scan")
    ]
    assert len(expected) >= 9 and loops.phases["pose"] == 2
    loops.start()
    try:
        origin = loops.loops["joints"].start_at
        assert {g: loop.start_at - origin for g, loop in loops.loops.items()} == pytest.approx(loops.offsets())
        wait_until(
            lambda: all(got[k] >= 3 for k in expected), timeout=30, what="every robot's stream", seen=lambda: dict(got)
        )
    finally:
        loops.stop()


@pytest.mark.slow
def test_a_stream_nobody_listens_to_is_not_built_until_someone_does(world, router, connect):
    """Nobody listens to base1's scans: they are neither read nor published (the sim's CPU), while its pose, which
    someone listens to, is; once someone subscribes, the scans go out too. The sim's own remote-only watch of
    every robot's joints (as a sim's terms and mirrors watch) counts as nobody."""
    fab, _ = router
    sim_fab = connect("sim", "sim-quiet")
    sim_fab.subscribe(keys.robot_stream_all(world, "joints"), lambda _k, _m: None, remote_only=True)
    loops = StreamLoops(sim_fab, SimWorld("combined", seed=3), threading.RLock(), Counter())
    got: Counter[str] = Counter()
    fab.subscribe(keys.robot_pose(world, "base1"), lambda key, msg: got.update([key.rsplit("/", 1)[1]]))
    scan = keys.robot_scan(world, "base1")
    wait_until(lambda: sim_fab.listened(keys.robot_pose(world, "base1")), timeout=30, what="the pose's subscriber")
    loops.start()
    try:
        wait_until(lambda: got["pose"] >= 50, timeout=30, what="base1's poses", seen=lambda: dict(got))
        built = sim_fab.seqs.under()  # the keys a header was made for
        assert scan not in built and keys.robot_stream(world, "arm1", "joints") not in built, sorted(built)
        fab.subscribe(scan, lambda key, msg: got.update([key.rsplit("/", 1)[1]]))
        wait_until(lambda: got["scan"] >= 5, timeout=30, what="base1's scans once listened to", seen=lambda: dict(got))
    finally:
        loops.stop()


@pytest.mark.slow
def test_streams_nobody_listens_to_still_tell_the_freeze_watch_the_sim_runs(world, router, connect):
    """The freeze watch takes a long gap between two publications for a freeze (and muzzles the sim, which then asks
    who holds the world and may take a new term): a sim skipping every stream, nobody listening, publishes nothing,
    and must not read as frozen when someone subscribes seconds later."""
    fab, _ = router
    sim_fab = connect("sim", "sim-beat")
    frozen: list[float] = []
    sim_fab.stamp.watch_freeze(0.3, frozen.append)
    loops = StreamLoops(sim_fab, SimWorld("combined", seed=3), threading.RLock(), Counter())
    got: Counter[str] = Counter()
    pose = keys.robot_pose(world, "base1")
    sub = fab.subscribe(pose, lambda key, msg: got.update(["pose"]))
    wait_until(lambda: sim_fab.listened(pose), timeout=30, what="the pose's subscriber")
    loops.start()
    try:
        wait_until(lambda: got["pose"] >= 5, timeout=30, what="base1's poses", seen=lambda: dict(got))
        sub.undeclare()
        wait_until(lambda: not sim_fab.listened(pose), timeout=30, what="nobody listening")
        published, ticks = sim_fab.counters["published"], loops.loops["joints"].stats.ticks
        wait_until(
            lambda: loops.loops["joints"].stats.ticks >= ticks + 100, timeout=30, what="1 s of ticks, nobody listening"
        )
        assert sim_fab.counters["published"] == published
        fab.subscribe(pose, lambda key, msg: got.update(["again"]))
        wait_until(
            lambda: got["again"] >= 20, timeout=30, what="base1's poses listened to again", seen=lambda: dict(got)
        )
        assert frozen == [] and not sim_fab.stamp.muzzled, frozen
    finally:
        loops.stop()
