"""Replicated authority across a healed network partition, on a LAN of namespaces.

The primary sim's cable is pulled (not SIGSTOP: the process runs on, its sockets stay open, its clock goes
on) for longer than the transport lease: the standby takes the world over with term 2. The cable goes back
in: the old primary hears the higher term and steps down to a standby of the new authority, and a recording
of the whole run shows exactly one term publishing at any instant.
"""

from __future__ import annotations

import signal

import pytest

from fabric.codec import decode
from fabric.fencing import is_authority_key
from robofabric.lab import Lab
from user_peer.recordings import iter_messages
from robofabric.testing import RemoteRoles, wait_until

pytestmark = [pytest.mark.lab, pytest.mark.slow]

LEASE = 2.0  # the fabric's transport lease (lease_ms default)


def test_a_primary_cut_off_past_the_lease_steps_down_when_the_partition_heals(lab: Lab):
    router_host, sa, sb, obs = lab.add_host("router"), lab.add_host("sa"), lab.add_host("sb"), lab.add_host("obs")
    ep = router_host.endpoint()
    router = router_host.start(["router", "--listen", ep], name="router")
    wait_until(lambda: "listening" in router.output() or not router.alive(), timeout=120, what="router listening")
    roles = RemoteRoles(obs.python(name="roles"), "demo", ep)  # the roles the sims show, seen from the observer's host
    sim = ["sim", "--scene", "combined", "--world", "demo", "--connect", ep]
    primary = sa.start([*sim, "--id", "sim-a"], name="sim-a")
    roles.wait("sim-a", "primary", term=1, timeout=120, seen=lambda: primary.output()[-800:])
    standby = sb.start([*sim, "--id", "sim-b", "--standby"], name="sim-b")
    roles.wait("sim-b", "standby", term=1, leader="sim-a", timeout=120, seen=lambda: standby.output()[-800:])
    recording = lab.log_dir / "failover.mcap"
    rec = obs.start(["record", "-o", str(recording), "-q", "--world", "demo", "--connect", ep], name="record")
    wait_until(
        lambda: recording.exists() and recording.stat().st_size > 2000,
        timeout=120,
        what="the recorder writing term 1",
        seen=lambda: rec.output()[-500:],
    )

    lab.cut(sa)
    try:
        roles.wait(
            "sim-b", "primary", term=2, timeout=LEASE + 20, seen=lambda: standby.output()[-800:]
        )  # the take-over
        assert primary.alive() and "stepping down" not in primary.output()  # cut off, it has heard nobody yet
        size = recording.stat().st_size
        wait_until(lambda: recording.stat().st_size > size + 2000, timeout=30, what="the recorder writing term 2")
    finally:
        lab.restore(sa)
    roles.wait(
        "sim-a", "standby", term=2, leader="sim-b", timeout=30, seen=lambda: primary.output()[-1500:]
    )  # stepped down
    assert "sim-b holds term 2; stepping down" in primary.output()
    assert "took over" not in primary.output() and "still the authority" not in primary.output()
    size = recording.stat().st_size
    wait_until(lambda: recording.stat().st_size > size + 2000, timeout=30, what="the recorder after the heal")
    rec.send_signal(signal.SIGTERM)
    wait_until(lambda: not rec.alive(), timeout=30, what="the recording finished")

    stamped = []
    for m in iter_messages(recording):
        if is_authority_key(m.key):
            h = decode(m.payload).header
            stamped.append((h.wall_ns, h.term, h.source))
    assert {(t, src) for _, t, src in stamped} == {(1, "sim-a"), (2, "sim-b")}, sorted(
        {(t, src) for _, t, src in stamped}
    )
    first2 = min(w for w, t, _ in stamped if t == 2)
    assert not [(w - first2) / 1e9 for w, t, _ in stamped if t == 1 and w > first2]  # one epoch at any instant
    assert primary.alive() and standby.alive()
