"""Scenario 4, two routers: router A with the sim on one host, router B with the users' side, B connected
to A over the LAN. Users on B see and drive everything; the A-B link drops: they are told the world is
gone; it heals: they carry on without restarting."""

from __future__ import annotations

import time
from typing import Iterator

import pytest

from robofabric.lab import Lab
from robofabric.testing import wait_until

pytestmark = [pytest.mark.lab, pytest.mark.slow]

LEASE = 2.0
JOIN = """
import time, numpy as np, user_peer
w = user_peer.connect(world="demo", connect=["{router}"], user="{user}", timeout=10.0, join_timeout=120)
arm = w.robot("arm1")
events = []
w.on_world(lambda alive, why: events.append((time.monotonic(), alive, why)))
"""


@pytest.fixture
def two_routers(lab: Lab) -> Iterator[dict]:
    a, b = lab.add_host("site-a"), lab.add_host("site-b")
    ra = a.start(["router", "--listen", a.endpoint()], name="router-a")
    wait_until(lambda: "listening" in ra.output() or not ra.alive(), timeout=120, what="router A")
    rb = b.start(["router", "--listen", b.endpoint(), "--connect", a.endpoint()], name="router-b")
    wait_until(lambda: "listening" in rb.output() or not rb.alive(), timeout=120, what="router B")
    sim = a.start(["sim", "--scene", "arm_cell", "--connect", a.endpoint()], name="sim")
    users = {name: lab.add_host(name).python(name=name) for name in ("alice", "bob")}
    for name, py in users.items():
        py.call(JOIN.format(router=b.endpoint(), user=name), timeout=180)
    yield {"lab": lab, "a": a, "b": b, "sim": sim, "users": users}


def test_users_behind_router_b_drive_lose_and_regain_the_world(two_routers):
    lab, users = two_routers["lab"], two_routers["users"]
    alice, bob = users["alice"], users["bob"]
    # users on B see and drive everything behind A
    assert alice.call("w.robots()") == ["arm1"]
    alice.call("arm.request(); arm.move_joints(np.full(6, 0.2), timeout=30); None", timeout=60)
    wait_until(
        lambda: bob.call("q = arm.joints; q is not None and bool(np.max(np.abs(q - 0.2)) < 1e-3)"),
        timeout=20,
        what="bob sees alice's move",
    )
    assert bob.call("arm.owner") == "alice"
    peers = two_routers["b"].robofabric("ps", "--json", "--connect", two_routers["b"].endpoint(), timeout=90)
    assert '"sim"' in peers.stdout and "alice" in peers.stdout, peers.stdout + peers.stderr

    # the A-B link drops (site A's cable): both users are told the world is gone
    t_cut = time.monotonic()
    lab.cut("site-a")
    for name, py in users.items():
        told = wait_until(
            lambda py=py: py.call("[t for t, alive, _ in events if not alive][-1:]"),
            timeout=30,
            what=f"{name} told the world is gone",
        )[0]
        assert told - t_cut <= LEASE + 1.5, f"{name} was told {told - t_cut:.2f} s after the link dropped"
        assert py.call("w.world_alive") is False
    gone_after = told - t_cut

    # it heals: the same sessions find the world again and alice drives on
    lab.restore("site-a")
    t_heal = time.monotonic()
    for name, py in users.items():
        assert py.call("w.wait_world(timeout=60)", timeout=90), f"{name} did not see the world come back"
    back_after = time.monotonic() - t_heal
    alice.call("arm.request(timeout=10); arm.move_joints(np.zeros(6), timeout=30); None", timeout=90)
    wait_until(
        lambda: bob.call("q = arm.joints; q is not None and bool(np.max(np.abs(q)) < 1e-3)"),
        timeout=20,
        what="bob sees alice's move after the heal",
    )
    print(f"two routers: world gone {gone_after:.2f} s after the cut; back {back_after:.2f} s after the heal")
