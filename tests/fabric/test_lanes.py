"""The lane (fabric.lanes): askers served in turn, each asker's queue and the lane bounded."""

from __future__ import annotations

import threading

from fabric.lanes import Lane
from robofabric.testing import wait_until


def test_askers_are_served_in_turn_not_in_arrival_order():
    gate, done = threading.Event(), []
    lane = Lane("t", per_asker=8, total=64)
    try:
        assert lane.submit("first", gate.wait)  # holds the worker while the queues fill
        for i in range(5):
            assert lane.submit("mallory", lambda i=i: done.append(f"m{i}"))
        assert lane.submit("bob", lambda: done.append("b0"))
        gate.set()
        wait_until(lambda: len(done) == 6, what="every job")
        assert done.index("b0") <= 1, done  # bob waited for one of mallory's five at most
    finally:
        lane.close()


def test_queues_are_bounded_and_a_failing_job_ends_nothing():
    gate = threading.Event()
    lane = Lane("t", per_asker=2, total=3)
    try:
        assert lane.submit("a", gate.wait)
        wait_until(lambda: lane.waiting() == 0, what="the worker to take the first job")
        assert lane.submit("a", lambda: 1 / 0) and lane.submit("a", lambda: None)
        assert not lane.submit("a", lambda: None)  # her queue is full
        assert lane.submit("b", lambda: None)
        assert not lane.submit("c", lambda: None)  # the lane is full
        ran = threading.Event()
        gate.set()
        wait_until(lambda: lane.submit("c", ran.set), what="room again")
        wait_until(ran.is_set, what="a job after the one that raised")
    finally:
        lane.close()
    assert not lane.submit("a", lambda: None)  # closed
