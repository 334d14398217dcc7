"""sim_peer.replica.replica_host.ReplicaHost in-process on a real router.

- A standby applies again, at its take-over, the commands sent after its last snapshot: its polling is
  held after one snapshot, so that a joint target sent afterwards is certainly not in it; the arm it set
  moving must go on to that target under the new authority, not back to the snapshot's.
- A standby that already follows a leader (a primary that stepped down) does not read a first view of
  the live sims that lacks it as the leader's death: it waits up to a lease for the leader's token.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import numpy as np
import pytest

from fabric import keys
from fabric.gate import OpenGate
from fabric.interfaces import Command, JointTarget
from robofabric.testing import client, wait_until
from sim_peer.replica import election as el
from sim_peer.replica.kept_commands import MAX_KEPT_BYTES, MAX_KEPT_COMMANDS
from sim_peer.replica.replica_host import ReplicaHost
from sim_peer.physics.world import SimWorld

pytestmark = pytest.mark.slow  # two sim hosts and a router: seconds


def _gate(fabric, world, restored):
    return OpenGate()


def _send(fab, key, msg) -> bool:
    fab.publish(key, msg)
    return False


def _host(world: str, port: int, peer_id: str, *, standby: bool) -> ReplicaHost:
    fab = client(world, port, kind="sim", peer_id=peer_id)
    return ReplicaHost(fab, SimWorld("combined", seed=1), _gate, standby=standby).open()


def test_a_joint_target_sent_after_the_last_snapshot_goes_on_under_the_new_authority(world, router, connect):
    port = router[1]
    primary = _host(world, port, "sim-a", standby=False)
    standby = _host(world, port, "sim-b", standby=True)
    try:
        follower = standby.follower
        wait_until(
            lambda: follower.snapshot is not None and follower.snapshot.header.source == "sim-a",
            timeout=20,
            what="a first snapshot",
        )
        # hold the polling: after the poll under way (if any) no snapshot comes until the take-over. Waited on by the
        # loop's wait, not by a new snapshot: at load the poll under way can time out, and none came (CI, 2026-12-01)
        follower.poll_s = 3600.0
        wait_until(
            lambda: follower.waiting_s == 3600.0, timeout=30, what="the last poll", seen=lambda: follower.waiting_s
        )
        held = follower.snapshot
        arm = standby.world.robots["arm1"]
        assert np.abs(held.robot("arm1").target).max() < 1e-9  # the snapshot knows no target but the spawn pose

        user = connect("user", "alice")
        target = np.radians([50.0, 20.0, -30.0, 20.0, 40.0, -20.0])
        cmd = Command("alice", 0, JointTarget(target, speed_scale=0.2))
        moving = lambda: "arm1" in follower.joints and np.abs(follower.joints["arm1"].dq).max() > 0.05  # noqa: E731
        # resent until the primary moves: a first put on a fresh publisher can go out before the route exists
        wait_until(
            lambda: moving() or _send(user, keys.robot_cmd(world, "arm1", "joints", "alice"), cmd),
            timeout=20,
            interval=0.3,
            what="the primary moving the arm",
        )
        assert follower.snapshot is held  # still the one from before the command
        assert any(isinstance(k.message, Command) for k in follower.commands)

        primary.close()
        primary.fabric.close()  # its token goes: the standby takes over
        wait_until(lambda: standby.takeovers, timeout=20, what="the take-over done")
        wait_until(
            lambda: np.abs(arm.ctrl.q - target).max() < 1e-3,
            timeout=30,
            what="the arm at the target sent after the snapshot",
            seen=lambda: (np.degrees(arm.ctrl.q).round(1), np.degrees(arm.ctrl.target).round(1)),
        )
        assert standby.peer.counters["accepted"] >= 1
    finally:
        for host in (standby, primary):
            host.close()
            host.fabric.close()


def test_a_standby_told_its_leader_waits_for_its_token_before_taking_over(world, router):
    """A primary that stepped down reopens as a standby of the leader it just heard; its fresh session's
    first liveliness query may not hold the leader's token yet (here: the token shows 0.3 s later). It
    must stay a standby, not take the world back with its own stale state."""
    port = router[1]
    leader: list = []
    late = threading.Timer(0.3, lambda: leader.append(client(world, port, kind="sim", peer_id="sim-x")))
    late.start()
    fab = client(world, port, kind="sim", peer_id="sim-a")
    host = ReplicaHost(fab, SimWorld("combined", seed=1), _gate, standby=True, term=2, leader="sim-x")
    try:
        host.open()
        assert host.role == el.STANDBY and host.election.leader == "sim-x" and host.peer is None, host.election
        assert "sim-x" in host.roles.live
        # and the leader going is still seen: the standby takes over with the next term
        late.join()
        leader[0].close()
        wait_until(lambda: host.takeovers, timeout=20, what="the take-over done", seen=lambda: host.election)
        assert host.election.term == 3
    finally:
        late.cancel()
        host.close()
        fab.close()
        for f in leader:
            f.close()


def test_a_standby_whose_leader_never_shows_takes_over_after_a_lease(world, router):
    """The leader died while we switched sessions: its token never shows, so no token going will ever
    be heard; after a lease the standby takes over."""
    fab = client(world, router[1], kind="sim", peer_id="sim-a")
    host = ReplicaHost(fab, SimWorld("combined", seed=1), _gate, standby=True, term=2, leader="sim-x")
    try:
        t0 = time.monotonic()
        host.open()
        wait_until(lambda: host.takeovers, timeout=20, what="the take-over done")
        assert host.election.term == 3
        assert time.monotonic() - t0 >= fab.config.lease_ms / 1000.0  # not on the first, partial view
    finally:
        host.close()
        fab.close()


def test_a_standby_keeps_the_commands_it_hears_within_the_caps(world, router):
    """A standby keeps what users send for its take-over through the host's follower, within the buffer's caps
    (count and bytes, oldest dropped first: a client flooding commands must not grow its memory)."""
    host = _host(world, router[1], "sim-b", standby=True)
    try:
        cmd = Command("alice", 0, JointTarget(np.zeros(6)))
        key = keys.robot_cmd(world, "arm1", "joints", "alice")
        for _ in range(MAX_KEPT_COMMANDS + 500):
            host.follower.keep(key, cmd, 100)
        kept = host.follower.commands
        assert len(kept) == MAX_KEPT_COMMANDS
        for _ in range(10):
            host.follower.keep(key, cmd, MAX_KEPT_BYTES // 4)  # big payloads: the byte cap
        assert kept.kept_bytes <= MAX_KEPT_BYTES and len(kept) <= 4
        assert kept.kept_bytes == sum(k.size for k in kept)
    finally:
        host.close()
        host.fabric.close()


def test_a_closed_standby_does_not_take_over(world, router):
    """A take-over decided as the host closes must not serve a world that is going away (it raised from
    its thread, or started a peer after close() had looked for one)."""
    host = _host(world, router[1], "sim-b", standby=True)
    host.close()
    try:
        host.take_over(time.monotonic())
        assert host.peer is None and not host.takeovers
    finally:
        host.fabric.close()


def test_a_take_over_keeps_the_former_leaders_samples_still_on_their_way_in(world, router):
    """At a take-over the election already names this sim the leader, yet samples of the former leader that
    reached the process before its token's loss may still wait in their subscription's thread. While the take-over
    drains, those are kept (the catch-up starts from the newest, and sim time never goes back); the drain ends
    only once they stopped coming; outside a drain, a sample of a sim not followed is not kept."""
    port = router[1]
    primary = _host(world, port, "sim-a", standby=False)
    standby = _host(world, port, "sim-b", standby=True)
    try:
        follower = standby.follower
        wait_until(lambda: "arm1" in follower.joints, timeout=20, what="the leader's joints")
        key = keys.robot_joints(world, "arm1")
        primary.close()
        primary.fabric.close()
        wait_until(lambda: standby.takeovers, timeout=20, what="the take-over done")
        last = follower.joints["arm1"]
        assert last.header.source == "sim-a" and standby.election.leader == "sim-b"
        late = replace(last, header=replace(last.header, stamp=last.header.stamp + 0.004))
        follower.on_joints(key, late)  # sim-a is not followed any more, and no take-over drains it
        assert follower.joints["arm1"] is last

        done: list[float] = []
        drain = threading.Thread(
            target=lambda: (follower.drain("sim-a", quiet_s=0.5, limit_s=5.0), done.append(time.monotonic()))
        )
        drain.start()
        wait_until(lambda: follower.former == "sim-a", timeout=5, what="the drain begun")
        fed: list[float] = []
        for _ in range(30):  # sim-a's samples still coming in, one every 5 ms, for 150 ms
            fed.append(time.monotonic())  # before: the drain's quiet counts from the sample's arrival
            follower.on_joints(key, late)
            time.sleep(0.005)
        drain.join(10)
        assert follower.joints["arm1"] is late  # kept while draining
        # the drain lasted until they stopped coming: never while they kept coming closer together than its quiet
        # (0.5 s). At load the feeding thread itself once paused longer than a quiet of 0.1 s, and the drain rightly
        # ended then: a gap that long is a stop, and then the drain must only have lasted a quiet
        assert done, "the drain did not end"
        if max(b - a for a, b in zip(fed, fed[1:])) < 0.4:
            assert done[0] >= fed[-1], (done, fed[-1])
        else:
            assert done[0] >= fed[0] + 0.5, (done, fed[0])
        follower.drained()
        assert follower.former is None
    finally:
        for host in (standby, primary):
            host.close()
            host.fabric.close()
