"""End to end with the real sim peer: the owner is SIGKILLed mid-motion, the next user owns the arm,
and the arm's joints continue from where they were (nothing resets on handover)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import Command, Event, JointState, JointTarget
from robofabric.testing import robofabric_cmd, wait_until

from ownership import OwnershipClient

pytestmark = pytest.mark.slow  # every test here starts processes or runs for seconds

HERE = Path(__file__).parent


def test_arm_continues_after_owner_is_killed(world, router, connect, procs):
    port = router[1]
    ep = f"tcp/127.0.0.1:{port}"
    sim = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
    fb = connect("user", "bob")
    wait_until(lambda: fb.live_peers("sim"), timeout=60, what="sim peer", seen=lambda: procs.output(sim)[-2000:])
    joints: list[JointState] = []
    fb.subscribe(keys.robot_joints(world, "arm1"), lambda k, m: joints.append(m), expected=JointState)
    events: list[Event] = []
    fb.subscribe(keys.event_all(world), lambda k, e: events.append(e), expected=Event)
    bob = OwnershipClient(fb, "bob", renew_s=0.1, timeout=10.0).start()
    wait_until(
        lambda: bob.record("arm1") is not None and joints, timeout=30, what="arm1 record and joints", seen=bob.snapshot
    )

    target = np.radians([60.0, 30.0, -40.0, 30.0, 50.0, -30.0])
    alice = procs.start(
        [
            sys.executable,
            str(HERE / "sim_user.py"),
            world,
            str(port),
            "alice",
            "arm1",
            ",".join(str(x) for x in target),
        ],
        name="alice",
    )
    wait_until(
        lambda: "sent" in procs.output(alice), timeout=30, what="alice's command", seen=lambda: procs.output(alice)
    )
    wait_until(
        lambda: bob.record("arm1").owner == "alice" and bob.record("arm1").state == "moving",
        timeout=20,
        what="alice owns a moving arm",
        seen=lambda: (bob.record("arm1"), procs.output(alice)),
    )
    out = bob.request("arm1")
    assert out.outcome == "denied" and "in motion" in out.reason, out
    assert bob.request("arm1", wait=True).outcome == "queued"
    fb.publish(
        keys.robot_cmd(world, "arm1", "joints", "bob"), Command("bob", bob.epoch("arm1"), JointTarget(np.zeros(6)))
    )
    wait_until(
        lambda: any(e.kind == "reject" and e.user == "bob" for e in events),
        what="bob's command rejected",
        seen=lambda: events[-5:],
    )

    procs.kill(alice)
    q_kill = np.asarray(joints[-1].q).copy()
    assert np.linalg.norm(q_kill) > 1e-3  # it had moved away from zero
    wait_until(lambda: bob.owns("arm1"), timeout=10, what="bob owns after alice's death", seen=bob.snapshot)
    n = len(joints)
    wait_until(lambda: len(joints) > n + 5, what="joints after handover")
    q_after = np.asarray(joints[-1].q)
    # continues from where it was: not reset to zero, still on its way to alice's target
    assert np.linalg.norm(q_after) >= np.linalg.norm(q_kill) - 1e-6, (q_kill, q_after)
    assert np.linalg.norm(q_after - target) <= np.linalg.norm(q_kill - target) + 1e-6, (q_kill, q_after)
    # bob commands it under his epoch
    fb.publish(keys.robot_cmd(world, "arm1", "joints", "bob"), Command("bob", bob.epoch("arm1"), JointTarget(q_after)))
    bob.close()
