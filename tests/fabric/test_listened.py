"""Fabric.listened: a stream is worth building only when someone listens. Another session's subscriber counts (as
soon as the router told this one), and so does one of this session's own that takes its samples; its own
``remote_only`` subscriptions (a sim's watch of every sim's joints) do not; a kept key's publisher cannot say."""

from __future__ import annotations

from fabric import keys
from robofabric.testing import wait_until


def test_a_remote_subscriber_makes_a_key_listened_and_its_undeclare_unlistened(world, connect):
    sim, user = connect("sim"), connect("tool")
    key = keys.robot_stream(world, "arm1", "joints")
    assert sim.listened(key) is False
    sub = user.subscribe(keys.robot_stream_all(world, "joints"), lambda _k, _m: None)
    wait_until(lambda: sim.listened(key), timeout=30, what="the user's subscription known to the sim")
    assert sim.listened(keys.robot_stream(world, "base1", "pose")) is False  # a key it does not take
    sub.undeclare()
    wait_until(lambda: not sim.listened(key), timeout=30, what="the undeclare known to the sim")


def test_its_own_remote_only_subscription_is_nobody_and_an_ordinary_one_is_someone(world, connect):
    sim = connect("sim")
    key = keys.robot_stream(world, "arm1", "joints")
    sim.subscribe(keys.robot_stream_all(world, "joints"), lambda _k, _m: None, remote_only=True)
    assert sim.listened(key) is False  # zenoh's own matching says yes here: a probe to remote subscribers does not
    assert sim.session.declare_publisher(key).matching_status.matching is True
    sim.subscribe(keys.robot_stream_all(world, "joints"), lambda _k, _m: None)
    assert sim.listened(key) is True


def test_a_kept_key_is_always_listened(world, connect):
    sim = connect("sim")
    key = keys.own(world, "arm1")  # records are kept for late joiners: their advanced publisher cannot say
    assert keys.cache_size(key)
    assert sim.listened(key) is True
