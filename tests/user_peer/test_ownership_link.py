"""The user is told when an object she owned is taken from her: a warning naming the new
owner and epoch, and ``on_lost`` callbacks; her own release tells her nothing."""

from __future__ import annotations

import logging

from robofabric.testing import wait_until
from ownership import Authority
from user_peer.ownership_link import OwnershipLink


def test_a_taken_object_is_announced_and_a_release_is_not(connect, caplog):
    auth = Authority(connect("sim", "authority"), {"arm": "exclusive"}, lease_s=2.0, grace_s=5.0).start()
    alice = OwnershipLink(connect("user", "alice"), "alice")
    bob = OwnershipLink(connect("user", "bob"), "bob")
    lost: list = []
    alice.on_lost(lambda obj, rec: lost.append((obj, rec.owner, rec.epoch)))
    bob.on_lost(lambda obj, rec: lost.append(("bob lost", obj, rec.owner)))
    try:
        with caplog.at_level(logging.WARNING, logger="robofabric.user"):
            epoch_a = alice.request("arm", timeout=5.0)
            epoch_b = bob.request("arm", timeout=5.0)  # a still arm: bob takes it over
            assert epoch_b > epoch_a
            # a deadline, not a pace: at load 4 beside the suite 5 s once passed with no word (run 8 of 2026-11-30)
            wait_until(lambda: lost, timeout=20.0, what="alice told she lost the arm", seen=lambda: alice.record("arm"))
            assert lost == [("arm", "bob", epoch_b)]
            assert f"lost ownership of arm: now owned by bob (epoch {epoch_b}" in caplog.text
            bob.release("arm", timeout=5.0)  # his own release: no notice
            wait_until(
                # a replica may hold no record yet: at load 4 bob's had heard none (his grant came in his request's reply)
                lambda: all(_epoch(link) > epoch_b for link in (alice, bob)),
                timeout=20.0,
                what="the release's record at both",
            )
            assert lost == [("arm", "bob", epoch_b)], lost
            assert caplog.text.count("lost ownership") == 1, caplog.text
    finally:
        alice.close()
        bob.close()
        auth.close()


def test_a_release_is_no_loss_when_a_record_naming_her_comes_in_between(connect, caplog):
    """The authority publishes her robot's record often (every renewal, every start and stop of motion): one
    naming her as owner that lands while her release is on its way must not turn the release into a loss
    (a class's students were all told "lost ownership" of both their robots as they closed)."""
    import threading

    auth = Authority(connect("sim", "authority"), {"arm": "exclusive"}, lease_s=2.0, grace_s=5.0).start()
    alice = OwnershipLink(connect("user", "alice"), "alice")
    lost: list = []
    alice.on_lost(lambda obj, rec: lost.append((obj, rec.owner, rec.epoch)))
    stop = threading.Event()

    def toggle() -> None:  # the arm starting and stopping: a record naming its owner each time
        moving = False
        while not stop.wait(0.0005):
            moving = not moving
            auth.update_motion("arm", moving)

    toggler = threading.Thread(target=toggle, daemon=True)
    try:
        with caplog.at_level(logging.WARNING, logger="robofabric.user"):
            auth.update_motion("arm", False)
            toggler.start()
            for _ in range(30):
                alice.request("arm", timeout=5.0)
                alice.release("arm", timeout=5.0)
            stop.set()
            toggler.join(2.0)
            wait_until(
                lambda: (r := alice.record("arm")) is not None and r.owner == "",
                timeout=5.0,
                what="the last release's record",
            )
        assert not lost, lost
        assert "lost ownership" not in caplog.text
    finally:
        stop.set()
        alice.close()
        auth.close()


def _epoch(link: OwnershipLink) -> int:
    rec = link.record("arm")
    return -1 if rec is None else rec.epoch
