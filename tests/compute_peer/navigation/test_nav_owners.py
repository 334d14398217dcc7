"""The navigation service's view of who owns each robot: the records its world's ownership authority publishes,
read by a replica that never asks for anything; nobody owns a robot the replica has no record of."""

from __future__ import annotations

from compute_peer.navigation.owners import OwnerWatch
from ownership import Authority, OwnershipClient
from robofabric.testing import wait_until


def test_the_owner_is_who_the_authority_says_and_nobody_before(connect):
    auth = Authority(connect("sim", "host"), {"base1": "exclusive"}, lease_s=5.0).start()
    alice = OwnershipClient(connect("user", "alice"), "alice", renew_s=0.1).start()
    watch = OwnerWatch(connect("compute", "compute-1"))
    try:
        wait_until(lambda: watch.client is not None, what="the watch's replica made")
        assert watch.owner_of("base1") is None  # free
        assert alice.request("base1").granted
        wait_until(lambda: watch.owner_of("base1") == "alice", what="alice's grant seen by the watch")
        assert watch.owner_of("arm9") is None  # no such robot: nobody's
        alice.release("base1")
        wait_until(lambda: watch.owner_of("base1") is None, what="the release seen by the watch")
    finally:
        watch.close()
        watch.close()  # a second close does nothing
        alice.close()
        auth.close()
