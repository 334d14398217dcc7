"""Scenario 1, the classroom: router, sim, compute, viewer, alice and bob on six hosts of one LAN.

The service hosts come from the lab file a person runs by hand (examples/lab/classroom.toml). Alice
and bob join from their own hosts as long-lived user sessions (the file's scripted users end as soon
as they are done, too soon to be listed) and run the paper's Test A and Test B (the code behind
``robofabric scenario``); then ``robofabric ps`` on alice's host must list every peer.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from robofabric.lab import Lab
from robofabric.lab.spec import load_lab, start_lab
from robofabric.testing import wait_until

pytestmark = [pytest.mark.lab, pytest.mark.slow]

CLASSROOM = Path(__file__).resolve().parents[2] / "examples" / "lab" / "classroom.toml"

JOIN = """
import time, user_peer
from user_peer import scenarios
from user_peer.errors import FabricUserError
w = user_peer.connect(world="demo", connect=["{router}"], user="{user}", timeout=10.0)
deadline = time.monotonic() + 120
while True:
    try:
        w.info(); break
    except FabricUserError:
        if time.monotonic() > deadline: raise
        time.sleep(0.5)
"""


def test_classroom_six_hosts_test_a_and_b_pass(lab: Lab):
    spec = load_lab(CLASSROOM)
    users = {"alice", "bob"}
    assert users <= {h.name for h in spec.hosts}
    spec = dataclasses.replace(
        spec, hosts=tuple(dataclasses.replace(h, run=()) if h.name in users else h for h in spec.hosts)
    )
    started = start_lab(spec, lab)
    router = lab.host("router").endpoint()
    alice, bob = lab.host("alice").python(name="alice"), lab.host("bob").python(name="bob")
    joins = [alice.submit(JOIN.format(router=router, user="alice")), bob.submit(JOIN.format(router=router, user="bob"))]
    for join in joins:
        join(timeout=240)
    test_a = alice.submit("r = scenarios.test_a(w); (r.ok, r.lines)")
    test_b = bob.submit("r = scenarios.test_b(w); (r.ok, r.lines)")
    ok_a, lines_a = test_a(timeout=300)
    ok_b, lines_b = test_b(timeout=300)
    assert ok_a, "Test A failed on alice's host:\n" + "\n".join(lines_a)
    assert ok_b, "Test B failed on bob's host:\n" + "\n".join(lines_b)

    want = {"router", "sim", "compute", "viewer"}

    def listing():
        out = lab.host("alice").robofabric("ps", "--json", "--connect", router, timeout=90)
        return json.loads(out.stdout)["peers"] if out.returncode == 0 else {"error": out.stderr[-500:]}

    seen: dict = {}

    def everyone() -> bool:
        seen.clear()
        seen.update(listing())
        return want <= set(seen) and users <= set(seen.get("user", []))

    wait_until(
        everyone, timeout=120, interval=1.0, what="robofabric ps on alice's host listing every peer", seen=lambda: seen
    )
    for name in want:  # every service host is still up: nothing crashed under the LAN's traffic
        assert started[name][0].alive(), f"{name} ended:\n{started[name][0].output()[-2000:]}"
