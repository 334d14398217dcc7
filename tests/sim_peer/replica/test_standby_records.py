"""A standby carries over the ownership records its leader published after its last snapshot.

Two :class:`~sim_peer.replica.replica_host.ReplicaHost` in-process on a real router, each with the real ownership
authority as its gate. The standby's polling is held after one snapshot; a user is then granted arm1 (a new epoch,
published on ``own/arm1``); the primary goes. The new authority must serve arm1 to the same owner at the same epoch,
never the snapshot's older one (the soak saw arm1's epoch go back 516 -> 515 across a fail-over on a cut).
"""

from __future__ import annotations

import pytest

from ownership import OwnershipClient
from robofabric.testing import client, wait_until
from sim_peer.cli import make_gate
from sim_peer.replica.replica_host import ReplicaHost
from sim_peer.physics.world import SimWorld

pytestmark = pytest.mark.slow  # two sim hosts, a user and a router: seconds


def _gate(fabric, world, restored, objects=True):
    return make_gate(fabric, world, True, restored, objects=objects)


def _host(world: str, port: int, peer_id: str, *, standby: bool) -> ReplicaHost:
    fab = client(world, port, kind="sim", peer_id=peer_id)
    return ReplicaHost(fab, SimWorld("combined", seed=1), _gate, standby=standby).open()


def test_a_grant_after_the_last_snapshot_keeps_its_owner_and_epoch_across_a_take_over(world, router, connect):
    port = router[1]
    primary = _host(world, port, "sim-a", standby=False)
    standby = _host(world, port, "sim-b", standby=True)
    alice = None
    try:
        follower = standby.follower
        wait_until(
            lambda: follower.snapshot is not None and follower.snapshot.header.source == "sim-a",
            timeout=20,
            what="a first snapshot",
        )
        follower.poll_s = 3600.0  # no snapshot after the poll under way (if any) until the take-over
        # the loop in its long wait (a new snapshot may not come: at load the poll under way can time out)
        wait_until(
            lambda: follower.waiting_s == 3600.0, timeout=30, what="the last poll", seen=lambda: follower.waiting_s
        )
        held = {r.object: r for r in follower.snapshot.records}["arm1"]
        assert held.owner == ""

        alice = OwnershipClient(connect("user", "alice"), "alice").start()
        granted = alice.request("arm1", timeout=10.0)
        assert granted.granted, granted
        epoch = alice.epoch("arm1")
        assert epoch > held.epoch
        wait_until(
            lambda: "arm1" in follower.records and follower.records["arm1"].epoch == epoch,
            timeout=10,
            what="the standby hearing the grant",
            seen=lambda: follower.records.get("arm1"),
        )
        assert {r.object: r for r in follower.snapshot.records}["arm1"].epoch == held.epoch  # not in the snapshot

        primary.close()
        primary.fabric.close()  # its token goes: the standby takes over
        wait_until(lambda: standby.takeovers and standby.gate is not None, timeout=20, what="the take-over done")
        rec = standby.gate.records()["arm1"]
        assert (rec.owner, rec.epoch) == ("alice", epoch), rec
        # what the new authority publishes is what alice holds: her epoch never went back
        wait_until(
            lambda: (alice.record("arm1") or held).header.source == "sim-b",
            timeout=10,
            what="sim-b's record of arm1",
            seen=lambda: alice.record("arm1"),
        )
        assert alice.epoch("arm1") == epoch and alice.owns("arm1")
    finally:
        if alice is not None:
            alice.close()
        for host in (standby, primary):
            host.close()
            host.fabric.close()
