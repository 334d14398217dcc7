"""Ownership over real Zenoh with the authority and users in separate processes."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import Command, Event, JointTarget
from robofabric.testing import wait_until

from ownership import OwnershipClient

pytestmark = pytest.mark.slow  # every test here starts processes or runs for seconds

HERE = Path(__file__).parent
LEASE, GRACE = 0.5, 10.0


def _start_host(procs, world, port, motion: Path):
    motion.write_text("still")
    host = procs.start(
        [sys.executable, str(HERE / "authority_host.py"), world, str(port), str(motion), str(LEASE), str(GRACE)],
        name="host",
    )
    wait_until(
        lambda: "ready" in procs.output(host), timeout=20, what="authority host ready", seen=lambda: procs.output(host)
    )
    return host


def _user(procs, world, port, user, obj="arm", wait=False):
    argv = [sys.executable, str(HERE / "user_proc.py"), world, str(port), user, obj] + (["wait"] if wait else [])
    p = procs.start(argv, name=user)
    _outcome(procs, p, user)
    return p


def _outcome(procs, p, user) -> str:
    """The outcome line the user process printed, once it is whole: an unbuffered ``print`` writes its words and
    its newline one by one, and a look between them saw ``outcome`` alone (the grouped run of 2026-11-30)."""
    line = wait_until(
        lambda: re.search(r"^outcome .*\n", procs.output(p), re.M),
        timeout=20,
        what=f"{user}'s whole outcome line",
        seen=lambda: procs.output(p),
    )
    return line.group(0)


def test_handover_enforcement_kill_and_reconnect(world, router, connect, procs, tmp_path):
    port = router[1]
    motion = tmp_path / "motion"
    _start_host(procs, world, port, motion)
    events: list[Event] = []
    watcher = connect("tool", "watcher")
    watcher.subscribe(
        keys.event_all(world), lambda k, e: events.append(e) if e.object == "arm" else None, expected=Event
    )

    a = _user(procs, world, port, "alice")
    assert "granted" in procs.output(a)

    fb = connect("user", "bob")
    bob = OwnershipClient(fb, "bob", renew_s=0.1).start()
    wait_until(
        lambda: bob.record("arm") and bob.record("arm").owner == "alice",
        what="bob's replica sees alice",
        seen=bob.snapshot,
    )

    # moving: denied, then queued
    motion.write_text("moving")
    wait_until(lambda: bob.record("arm").state == "moving", what="arm moving in replica", seen=bob.snapshot)
    out = bob.request("arm")
    assert out.outcome == "denied" and "in motion" in out.reason and "alice" in out.reason, out
    out = bob.request("arm", wait=True)
    assert (out.outcome, out.position) == ("queued", 1), out

    # bob's commands are rejected while alice owns the arm
    def send(user, epoch):
        fb.publish(keys.robot_cmd(world, "arm", "joints", user), Command(user, epoch, JointTarget(np.zeros(3))))

    send("bob", bob.epoch("arm"))
    wait_until(
        lambda: any(e.kind == "reject" and e.user == "bob" and "owned by alice" in e.reason for e in events),
        what="bob's command rejected",
        seen=lambda: events,
    )

    # alice SIGKILLed: bob owns the arm (the arm is still moving: nothing reset)
    epoch_alice = bob.epoch("arm")
    procs.kill(a)
    wait_until(
        lambda: bob.record("arm").owner == "bob",
        timeout=LEASE + 3.0,
        what="bob owns after alice's death",
        seen=bob.snapshot,
    )
    assert bob.record("arm").epoch > epoch_alice
    assert bob.record("arm").state == "moving"

    # stale epoch rejected, current epoch accepted
    send("bob", epoch_alice)
    wait_until(
        lambda: any(e.kind == "reject" and "stale epoch" in e.reason for e in events),
        what="stale epoch rejected",
        seen=lambda: events,
    )
    send("bob", bob.epoch("arm"))
    wait_until(
        lambda: any(e.kind == "accept" and e.user == "bob" for e in events),
        what="bob's command accepted",
        seen=lambda: events,
    )

    # alice comes back within grace: queued at her old (first) place, bob keeps the arm past several leases
    a2 = procs.start(
        [sys.executable, str(HERE / "user_proc.py"), world, str(port), "alice", "arm", "wait"], name="alice2"
    )
    wait_until(lambda: bob.record("arm").queue == ("alice",), timeout=20, what="alice queued again", seen=bob.snapshot)
    assert "queued at position 1" in _outcome(procs, a2, "alice2")
    deadline = bob.record("arm").lease_expiry
    wait_until(lambda: bob.record("arm").lease_expiry > deadline + LEASE, what="bob renews", seen=bob.snapshot)
    assert bob.record("arm").owner == "bob"

    # still: a request hands it over at once
    motion.write_text("still")
    wait_until(lambda: bob.record("arm").state == "still", what="arm still", seen=bob.snapshot)
    fc = connect("user", "carol")
    carol = OwnershipClient(fc, "carol").start()
    assert carol.record("arm").owner == "bob"  # late joiner's replica is filled by the query at once
    out = carol.request("arm")
    assert out.outcome == "granted", out
    wait_until(lambda: bob.record("arm").owner == "carol", what="bob sees carol", seen=bob.snapshot)
    bob.close()
    carol.close()
