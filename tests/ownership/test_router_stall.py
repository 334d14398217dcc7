"""A stalled router is not the owners' fault, end to end in a ``secure init`` class world.

A login declaring 20,000 subscribers and closing stalls the router for many seconds, far past the 2 s
transport lease: the router closes its clients' links and drops their liveliness tokens, and the sim's
authority saw bob leave and come back (his base released, then restored, epoch 5 -> 7). Pausing the router
(SIGSTOP) for 8 s makes the same stall in seconds. Real router, real sim, alice and bob in this process.
"""

from __future__ import annotations

import os
import signal
import time
import uuid

import pytest

from fabric import keys
from fabric.interfaces import OwnershipRecord
from robofabric.secure import init
from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow

GRACE_S = 10.0  # the authority's default grace: a held owner whose token never came back would leave after it


def test_a_router_paused_8_s_releases_and_restores_no_robot(tmp_path):
    import user_peer

    world = f"stall{uuid.uuid4().hex[:6]}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    made = init(tmp_path / "class", users=["alice", "bob"], listen=[ep])
    files = made.clients
    with ProcessGroup(tmp_path) as procs:
        router = procs.start(robofabric_cmd("router", "--zenoh-config", str(made.router)), name="router")
        wait_until(
            lambda: "listening" in procs.output(router), timeout=30, what="router", seen=lambda: procs.output(router)
        )
        sim = procs.start(
            robofabric_cmd("sim", "--scene", "combined", "--world", world, "--zenoh-config", str(files["sim"])),
            name="sim",
        )
        alice = user_peer.connect(world=world, zenoh_config=str(files["alice"]), timeout=10.0, join_timeout=90.0)
        bob = user_peer.connect(world=world, zenoh_config=str(files["bob"]), timeout=10.0)
        try:
            arm, base = alice.robot("arm1"), bob.robot("base1")
            arm.request(timeout=10)
            base.request(timeout=10)
            held = {"arm1": ("alice", arm.record.epoch), "base1": ("bob", base.record.epoch)}
            changes: list[str] = []

            def on(key: str, rec: OwnershipRecord) -> None:
                if rec.object in held and (rec.owner, rec.epoch) != held[rec.object]:
                    changes.append(f"{rec.object}: {held[rec.object]} -> {rec.owner or 'free'}@{rec.epoch}")

            alice.fabric.subscribe(keys.own_all(world), on, expected=OwnershipRecord)
            os.kill(router.pid, signal.SIGSTOP)
            try:
                time.sleep(8.0)  # the stall itself: four transport leases with the router answering nobody
            finally:
                os.kill(router.pid, signal.SIGCONT)
            resumed = time.monotonic()
            # every link the router cut comes back: both users' tokens are seen again
            wait_until(
                lambda: {("user", "alice"), ("user", "bob")} <= set(bob.fabric.live_peers("user")),
                timeout=60,
                what="alice's and bob's tokens after the stall",
                seen=lambda: bob.fabric.live_peers("user"),
            )
            # a held owner whose token did not come back would leave after grace: watch past it for any change
            while time.monotonic() < resumed + GRACE_S + 2.0:
                assert not changes, changes
                time.sleep(0.2)
            assert not changes, changes
            assert (arm.record.owner, arm.record.epoch) == held["arm1"] and (
                base.record.owner,
                base.record.epoch,
            ) == held["base1"]
            start = base.xy_theta
            end = base.drive(0.2, 0.0, 1.0)  # bob still drives his base with the epoch he had
            assert abs(end[0] - start[0]) + abs(end[1] - start[1]) > 0.05, (start, end)
            assert "own_released" not in procs.output(sim), procs.output(sim)[-2000:]
        finally:
            alice.close()
            bob.close()
            procs.kill(sim, sig=signal.SIGTERM)
