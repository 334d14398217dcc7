"""A standby paused past the lease (SIGSTOP, SIGCONT) wakes with a link the router dropped and a state that stops
where it froze: every token it saw goes at once, its leader's too. It waits for its link and the tokens to come
back (its own heartbeat tells it was frozen), finds its leader alive and follows it again; it takes nothing over,
and the primary serves on under term 1."""

from __future__ import annotations

import os
import signal

import pytest

from fabric import keys
from fabric.interfaces import JointState
from robofabric.testing import SimRoles, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow


def test_a_standby_paused_past_the_lease_follows_again_and_takes_nothing_over(world, router, connect, procs):
    ep = f"tcp/127.0.0.1:{router[1]}"
    roles = SimRoles(connect("tool", "roles"))  # the roles the sims show (their role tokens), from the start
    primary = procs.start(
        robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep, "--id", "sim-a"), name="sim-a"
    )
    roles.wait("sim-a", "primary", term=1, timeout=90, seen=lambda: procs.output(primary)[-1500:])
    standby = procs.start(
        robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep, "--id", "sim-b", "--standby"),
        name="sim-b",
    )
    roles.wait("sim-b", "standby", term=1, leader="sim-a", timeout=90, seen=lambda: procs.output(standby)[-1500:])
    watch = connect("tool", "watch")
    joints: list[JointState] = []
    watch.subscribe(keys.robot_joints(world, "arm1"), lambda k, m: joints.append(m), expected=JointState)
    lease = watch.config.lease_ms / 1000.0
    wait_until(lambda: joints, timeout=30, what="the primary's joints")
    os.kill(standby.pid, signal.SIGSTOP)
    try:
        # the router drops the frozen standby: its token goes (a lease), and as long again for good measure
        wait_until(
            lambda: ("sim", "sim-b") not in watch.live_peers("sim"), timeout=30, what="the router dropping sim-b"
        )
        n = len(joints)
        wait_until(lambda: len(joints) > n + int(100 * lease), timeout=30, what="a lease of the primary's joints")
    finally:
        os.kill(standby.pid, signal.SIGCONT)
    # its link, then the tokens come back; three leases and more of the primary serving on (a take-over would come
    # within the first of them: the loss of the tokens is read at once)
    n = len(joints)
    wait_until(
        lambda: roles.ever("sim-b", "primary") or len(joints) > n + int(100 * 4 * lease),
        timeout=60,
        what="four leases of the primary's joints after SIGCONT",
        seen=lambda: procs.output(standby)[-1500:],
    )
    assert not roles.ever("sim-b", "primary"), procs.output(standby)[-1500:]
    roles.wait(
        "sim-b", "standby", term=1, leader="sim-a", timeout=30, seen=lambda: procs.output(standby)[-1500:]
    )  # back
    assert {(m.header.source, m.header.term) for m in joints[n:]} == {("sim-a", 1)}
    assert standby.poll() is None, procs.output(standby)[-1500:]
