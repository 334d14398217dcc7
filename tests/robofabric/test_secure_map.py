"""A student cannot harm the class's map, in a ``secure init`` world: router, sim and compute peer as
their own processes under their own logins, bob and the instructor carol logged in as themselves, mallory as a
lying student.

The issue saw her ``build`` with threshold 0.001 on ``srv/map/map/by/mallory`` republish the class's map with every
seen cell occupied (every plan failed until the instructor rebuilt it), and builds under 1,400 new map names grow
the compute peer from 142 to 528 MB for good.
"""

from __future__ import annotations

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import MapReply, MapRequest, OccupancyGrid, PlanReply, PlanRequest
from fabric.interfaces import ServiceError
from robofabric.testing import wait_until
from tests.robofabric.test_secure_world import Seen, secure, secure_compute  # noqa: F401 (fixtures)

pytestmark = pytest.mark.slow


def test_mallory_builds_only_maps_of_her_own_checked_and_capped(secure, secure_compute):  # noqa: F811
    import user_peer
    from compute_peer.navigation.map_store import MAX_MAPS_PER_USER
    from user_peer import services

    w = secure.world
    mallory = secure.fabric("mallory")
    carol = secure.fabric("carol")
    watcher = secure.fabric("viewer", kind="viewer", peer_id="watch-maps")
    published = Seen(watcher, f"{keys.world_root(w)}/map/*", OccupancyGrid)
    bob = user_peer.connect(world=w, zenoh_config=str(secure.files["bob"]), timeout=10.0)
    try:
        base = bob.robot("base1")
        base.wait_for("pose", timeout=30)
        base.request(timeout=10)
        base.drive(0.0, 0.8, 2.0 * np.pi / 0.8)  # a turn in place while the compute peer maps (Test B's start)
        status = lambda: services.map_request(bob.fabric, "status", user="bob", timeout=10.0)  # noqa: E731
        wait_until(lambda: status().scans > 20, timeout=60, what="scans in the class's map")
        # the instructor builds the class's map (the staff's form), and bob plans on it
        built = carol.rpc.call(keys.srv(w, "map", "map"), MapRequest("build"), timeout=10.0, expected=MapReply)
        assert built.name == "map" and (built.grid.cells == 0).any()
        plan = PlanRequest("base1", goal=np.array([-2.5, 0.5, np.pi]), direction="both")  # Test B's goal
        assert (
            bob.fabric.rpc.call(keys.srv_asked(w, "plan", "base1", "bob"), plan, timeout=30.0, expected=PlanReply).map
            == "map"
        )
        wait_until(lambda: published.messages(), timeout=20, what="the class's map published")

        asked = keys.srv_asked(w, "map", "map", "mallory")
        # her issue-30 build: refused with the reason, and so are the other bad parameters
        for req, reason in (
            (MapRequest("build", threshold=0.001), r"threshold 0.001 is outside \[0.5, 0.99\]"),
            (MapRequest("build", threshold=1.0), r"threshold 1 is outside \[0.5, 0.99\]"),
            (MapRequest("build", name="m" * 80), "characters long; at most 64"),
        ):
            with pytest.raises(ServiceError, match=reason):
                mallory.rpc.call(asked, req, timeout=10.0, expected=MapReply)
        # a build she may make is hers: map/mallory.map, and the class's map stays as the instructor built it
        mine = mallory.rpc.call(asked, MapRequest("build", threshold=0.5), timeout=10.0, expected=MapReply)
        assert mine.name == "mallory.map"
        # new names past her cap are refused with the reason; what the compute peer holds stays bounded
        refused = 0
        for i in range(3 * MAX_MAPS_PER_USER):
            try:
                mallory.rpc.call(
                    asked, MapRequest("build", name=f"m{i}", threshold=0.5), timeout=10.0, expected=MapReply
                )
            except ServiceError as exc:
                assert f"mallory holds {MAX_MAPS_PER_USER} maps, the most one user may" in exc.reason, exc.reason
                refused += 1
        assert refused == 2 * MAX_MAPS_PER_USER + 1
        wait_until(
            lambda: f"{keys.world_root(w)}/map/mallory.map" in {k for k, _ in published.items},
            timeout=20,
            what="her map published",
        )
        theirs = sorted({k.rsplit("/", 1)[1] for k, _ in published.items})
        assert theirs == ["mallory.m0", "mallory.m1", "mallory.m2", "mallory.map", "map"], theirs
        with pytest.raises(ServiceError, match="no map named 'mallory.m5'"):
            mallory.rpc.call(asked, MapRequest("get", name="mallory.m5"), timeout=10.0, expected=MapReply)
        # the class's map is the one the instructor built, published once, and bob still plans on it
        got = bob.fabric.rpc.call(
            keys.srv_asked(w, "map", "map", "bob"), MapRequest("get"), timeout=10.0, expected=MapReply
        )
        assert np.array_equal(got.grid.cells, built.grid.cells)
        assert len([k for k, _ in published.items if k.endswith("/map/map")]) == 1
        again = bob.fabric.rpc.call(keys.srv_asked(w, "plan", "base1", "bob"), plan, timeout=30.0, expected=PlanReply)
        assert again.map == "map" and len(again.path) > 1
    finally:
        bob.close()
