"""A login declaring thousands of subscribers and closing must not cost anyone a robot.

mallory's 6,000 declarations stall the router 7-8 s when she closes, long enough for alice's and bob's
leases to expire. The router cannot be told to bound declarations (zenoh 1.x has no such limit); the authority must
not expire leases while it cannot hear anyone (the rule for a paused authority, applied to a stalled
router). Real router with ``secure init``'s config, a real sim, mallory in her own process."""

from __future__ import annotations

import pytest

from robofabric.bench.declflood import run_flood, table

pytestmark = pytest.mark.slow


def test_a_declare_and_close_flood_leaves_every_owner_owning(tmp_path):
    (r,) = run_flood([6000], tmp_path, settle=2.0)
    print(table([r]))
    assert r.declare_s == r.declare_s, "mallory never said she had declared"  # not NaN
    # not even released and restored
    assert r.alice_owns and r.bob_owns and r.losses == 0 and r.changes == 0, (table([r]), r.changed)
