"""A going the authority hears just after its own link came back is the link's, not the user's: she keeps what she
owns. Real zenoh on loopback: the router is closed and opened again on its port, and both clients reconnect by
themselves; the old link's going of alice's token is then told late, as zenoh may tell it.

A class's sim, starved past its transport lease, lost its link for 0.0 s and released 33 bases as "left": the
goings of the old link came 0.2-0.5 s after the new link was up (`robofabric bench console --pages 4 --clients 32`,
2026-12-02)."""

from __future__ import annotations

import pytest

from fabric import keys
from fabric.interfaces import OwnershipRecord
from fabric.session import Fabric
from ownership.authority import Authority
from ownership.client import OwnershipClient
from ownership.hearing import CONFIRM_SLACK_S
from robofabric.testing import client, free_port, router_config, wait_until


def test_a_users_going_heard_just_after_the_authoritys_link_came_back_releases_nothing(world):
    port = free_port()
    routers = [Fabric(router_config(world, port), kind="router", peer_id="router")]
    host, user = client(world, port, kind="sim", peer_id="host"), client(world, port, kind="user", peer_id="alice")
    auth = Authority(host, {"base": "exclusive"}, lease_s=2.0, grace_s=10.0).start()
    alice = OwnershipClient(user, "alice", renew_s=0.5).start()
    changes: list[str] = []
    window = auth.hearing.lease_s + CONFIRM_SLACK_S
    try:
        assert alice.request("base").granted
        user.subscribe(
            keys.own_all(world),
            lambda k, rec: changes.append(f"{rec.owner or 'free'}@{rec.epoch}"),
            expected=OwnershipRecord,
        )
        for _ in range(3):  # a cut whose own goings settled only after the window (a slow box) is made again
            routers[-1].close()
            wait_until(lambda: not host._linked(), what="the authority's link down")
            routers.append(Fabric(router_config(world, port), kind="router", peer_id="router"))
            wait_until(lambda: host._linked() and user._linked(), timeout=30, what="both links back")
            # the cut's own goings may race its loss and release her base (restored when her token is back, a new
            # epoch): only what follows the going told below is judged
            wait_until(
                lambda: auth.records()["base"].owner == "alice" and not auth.hearing.pending,
                timeout=30,
                what="alice owning her base again, confirmed",
                seen=lambda: (auth.records()["base"], changes),
            )
            before, heard = auth.records()["base"], len(changes)
            if host.relinked_within(window - 0.5):
                break
        else:
            pytest.fail(f"the links never settled within {window - 0.5:.1f} s of their return, in three cuts")
        auth._watch.heard(keys.peer(world, "user", "alice"), False)  # the old link's going, told after the new link
        # her token is there: the going's check (or her token's return) confirms her, and she was never released
        wait_until(
            lambda: not auth.hearing.pending,
            timeout=30,
            what="alice confirmed",
            seen=lambda: (auth.records()["base"], changes),
        )
        rec = auth.records()["base"]
        assert (rec.owner, rec.epoch) == ("alice", before.epoch), (rec, changes)
        assert all(c == f"alice@{before.epoch}" for c in changes[heard:]), changes
    finally:
        alice.close()
        auth.close()
        user.close()
        host.close()
        routers[-1].close()
