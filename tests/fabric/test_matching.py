"""fabric.matching: a wait for a subscriber ends when zenoh says one matches (any, or every publisher), when
time is up, or when told to stop; a publisher that cannot say (zenoh.ext's advanced one) never counts as matched."""

from __future__ import annotations

import threading

import zenoh

from fabric import keys
from fabric.matching import is_matched, wait_matched


def _waiting(pubs, timeout: float, **kw) -> tuple[threading.Thread, list[bool]]:
    result: list[bool] = []
    t = threading.Thread(target=lambda: result.append(wait_matched(pubs, timeout, **kw)))
    t.start()
    return t, result


def test_a_subscriber_declared_during_the_wait_ends_it_matched(world, connect):
    sender, receiver = connect("tool"), connect("tool")
    key = keys.world_root(world) + "/m/one"
    pub = sender.session.declare_publisher(key)
    assert not is_matched(pub)
    t, result = _waiting([pub], 30.0)
    sub = receiver.session.declare_subscriber(key, lambda _s: None)
    t.join(35)
    assert result == [True] and is_matched(pub)
    sub.undeclare()
    pub.undeclare()


def test_nobody_listening_is_not_matched_once_time_is_up(world, connect):
    fab = connect("tool")
    pub = fab.session.declare_publisher(keys.world_root(world) + "/m/none")
    assert wait_matched([pub], 0.2) is False
    assert fab.wait_matching(keys.world_root(world) + "/m/none2", 0.2) is False  # the session's wait is this one
    pub.undeclare()


def test_every_waits_for_each_publisher_and_any_for_one(world, connect):
    sender, receiver = connect("tool"), connect("tool")
    root = keys.world_root(world)
    a, b = sender.session.declare_publisher(root + "/m/a"), sender.session.declare_publisher(root + "/m/b")
    sub = receiver.session.declare_subscriber(root + "/m/a", lambda _s: None)
    assert wait_matched([a, b], 30.0) is True  # a alone is enough
    assert wait_matched([a, b], 0.2, every=True) is False  # b has nobody
    t, result = _waiting([a, b], 30.0, every=True)
    sub_b = receiver.session.declare_subscriber(root + "/m/b", lambda _s: None)
    t.join(35)
    assert result == [True]
    for r in (sub, sub_b, a, b):
        r.undeclare()


def test_a_stop_ends_the_wait_unmatched(world, connect):
    fab = connect("tool")
    pub = fab.session.declare_publisher(keys.world_root(world) + "/m/stop")
    stop = threading.Event()
    t, result = _waiting([pub], 300.0, stop=stop)
    stop.set()
    t.join(30)
    assert not t.is_alive() and result == [False]
    pub.undeclare()


def test_an_advanced_publisher_does_not_count_as_matched(world, connect):
    sender, receiver = connect("tool"), connect("tool")
    key = keys.world_root(world) + "/m/latched"
    adv = zenoh.ext.declare_advanced_publisher(sender.session, key, cache=zenoh.ext.CacheConfig(max_samples=1))
    sub = receiver.session.declare_subscriber(key, lambda _s: None)
    assert not is_matched(adv) and wait_matched([adv], 0.2) is False
    assert wait_matched([], 0.1) is False  # nothing to ask is nothing matched
    sub.undeclare()
    adv.undeclare()
