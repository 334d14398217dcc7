"""A sim tells its own dead link from a leader's death by asking its router (a round trip a dead link cannot
make): the router answers on a live link, and nothing answers once the router is gone."""

from __future__ import annotations

import pytest

from fabric.session import Fabric
from robofabric.testing import client, free_port, router_config, wait_until
from sim_peer.replica.roles import router_answers

pytestmark = pytest.mark.slow


def test_the_router_answers_on_a_live_link_and_nothing_does_once_it_is_gone():
    port = free_port()
    router = Fabric(router_config("w", port), kind="router", peer_id="router")
    with client("w", port, kind="sim", peer_id="sim-b") as fab:
        try:
            assert router_answers(fab, 2.0)
        finally:
            router.close()
        wait_until(lambda: not fab.connected(), timeout=30, what="the link down")
        assert not router_answers(fab, 0.3)
