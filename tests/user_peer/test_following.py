"""Which robots a user peer decodes: a followed robot's streams reach ``latest``; once unfollowed, nothing it
publishes is delivered or decoded here, while another followed robot goes on; followed again, it comes again.

A real router and real sessions on loopback (the sim's side is a session publishing as a sim does)."""

from __future__ import annotations

import numpy as np

from fabric import keys
from fabric.interfaces import Path, Pose
from robofabric.testing import wait_until
from user_peer.following import Following
from user_peer.latest import Latest


def _pose(x: float) -> Pose:
    return Pose(position=np.array([x, 0.0, 0.0]))


def _x(latest: Latest, world: str, rid: str) -> float | None:
    p = latest.get(keys.robot_stream(world, rid, "pose"))
    return None if p is None else float(p.position[0])


def test_an_unfollowed_robot_is_no_longer_decoded_and_follows_again(world, connect):
    sim, user = connect("sim", "sim"), connect("user", "alice")
    latest = Latest()
    following = Following(user, world, latest)
    assert following.robot("base1") and following.robot("base2")
    assert not following.robot("base1")  # already followed
    assert following.robots == {"base1", "base2"}

    published = [0]  # bursts published: one pose of each robot

    def publish(x: float) -> None:
        published[0] += 1
        for rid in ("base1", "base2"):
            sim.publish(keys.robot_stream(world, rid, "pose"), _pose(x))

    def both_at(x: float) -> bool:
        publish(x)
        return _x(latest, world, "base1") == x and _x(latest, world, "base2") == x

    wait_until(
        lambda: both_at(1.0),
        timeout=20,
        what="both robots' poses",
        seen=lambda: (_x(latest, world, "base1"), _x(latest, world, "base2")),
    )
    # Fences, one per subscription: each subscription's callback runs on a thread of its own (zenoh-python's callbacks
    # are indirect), fed in order, but the two threads not in step with each other. A marker kept says that its
    # subscription has decoded everything sent before it. Without base1's, a base1 pose queued before the unfollow
    # was decoded after base2's marker and counted as one more (the whole suite once counted 23 of 22).
    sim.publish(keys.robot_stream(world, "base1", "pose"), _pose(1.25))  # once: its publisher's route is known by now
    wait_until(
        lambda: _x(latest, world, "base1") == 1.25,
        timeout=20,
        what="base1's marker",
        seen=lambda: _x(latest, world, "base1"),
    )

    assert following.unfollow("base1")
    assert not following.unfollow("base1")  # no longer followed
    assert following.robots == {"base2"}
    sim.publish(keys.robot_stream(world, "base2", "pose"), _pose(1.5))
    wait_until(
        lambda: _x(latest, world, "base2") == 1.5,
        timeout=20,
        what="base2's marker",
        seen=lambda: _x(latest, world, "base2"),
    )
    decoded, bursts = user.counters["received"], published[0]
    # base2 still followed: its poses after the unfollow arrive, base1's (published with them) never do
    wait_until(
        lambda: publish(2.0) or _x(latest, world, "base2") == 2.0,
        timeout=20,
        what="base2's pose after base1 was unfollowed",
        seen=lambda: _x(latest, world, "base2"),
    )
    for _ in range(20):
        publish(2.0)
    sent = published[0] - bursts
    wait_until(
        lambda: user.counters["received"] - decoded >= sent,
        timeout=20,
        what="base2's poses decoded",
        seen=lambda: (user.counters["received"] - decoded, sent),
    )
    assert _x(latest, world, "base1") == 1.25  # what was kept stays; nothing newer was decoded
    assert user.counters["received"] - decoded == sent  # base2's poses only, none of base1's sent with them

    # a path planned while unfollowed comes at once (latched) when it is followed again; then its poses too
    sim.publish(
        keys.robot_stream(world, "base1", "path"),
        Path(x=np.array([0.0, 1.0]), y=np.array([0.0, 0.5]), theta=np.array([0.0, 0.0])),
    )
    assert following.robot("base1") and following.robots == {"base1", "base2"}
    wait_until(
        lambda: latest.get(keys.robot_stream(world, "base1", "path")) is not None,
        timeout=20,
        what="base1's latched path once followed again",
    )
    wait_until(
        lambda: publish(3.0) or _x(latest, world, "base1") == 3.0,
        timeout=20,
        what="base1's pose once followed again",
        seen=lambda: _x(latest, world, "base1"),
    )
