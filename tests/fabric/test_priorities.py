"""Ownership and refusal events reach a slow subscriber through a flood of data (fabric.publishers.priority_for).

A subscriber that cannot keep up (a student's busy laptop, the soak's observer under a CPU hog) fills the
router's queue toward it with scans; zenoh drops what does not fit. At the default priority the events that
explain an ownership change were dropped with the scans while the record itself, in the high-priority queue,
arrived: the soak's checker saw arm1 pass to nobody with no release announced (CI, 2026-11-29)."""

from __future__ import annotations

import threading
import time

import pytest

import zenoh

from fabric import keys
from fabric.interfaces import Event, EventKind
from fabric.publishers import priority_for
from robofabric.testing import wait_until


def test_ownership_and_reject_events_go_with_the_records_ahead_of_data():
    w = "w1"
    assert priority_for(keys.own(w, "arm1")) == zenoh.Priority.INTERACTIVE_HIGH
    assert priority_for(keys.event(w, "own", "arm1")) == zenoh.Priority.INTERACTIVE_HIGH
    assert priority_for(keys.event(w, "reject", "arm1")) == zenoh.Priority.INTERACTIVE_HIGH
    assert priority_for(keys.event(w, "reject")) == zenoh.Priority.INTERACTIVE_HIGH  # an unknown robot's refusals
    assert priority_for(keys.event(w, "clamp", "arm1")) is None
    assert priority_for(keys.robot_scan(w, "base1")) is None


@pytest.mark.slow  # seconds: a scan flood that overwhelms a subscriber
def test_every_ownership_event_reaches_a_subscriber_that_a_scan_flood_overwhelms(world, connect):
    sim, slow = connect("sim", "sim-a"), connect("user", "carol")
    got: list[int] = []
    slow.subscribe_raw(keys.robot_scan(world, "base1"), lambda s: time.sleep(0.005))
    slow.subscribe(keys.event_all(world), lambda k, m: got.append(int(m.data["n"])), expected=Event)
    flood = sim.session.declare_publisher(keys.robot_scan(world, "base1"))  # zenoh's default: data, dropped when full
    wait_until(lambda: (sim.reports.emit(_event(-1), "own", "arm1"), got)[1], what="the subscription in place")
    stop = threading.Event()

    def flooder() -> None:
        payload = b"x" * 60_000
        while not stop.is_set():
            flood.put(payload)

    thread = threading.Thread(target=flooder, daemon=True)
    thread.start()
    n = 200
    try:
        for i in range(n):
            sim.reports.emit(_event(i), "own", "arm1")
            time.sleep(0.01)
    finally:
        stop.set()
        thread.join(timeout=10)
    wait_until(
        lambda: set(range(n)) <= set(got),
        timeout=30,
        what="every ownership event",
        seen=lambda: f"{len(set(got) & set(range(n)))} of {n}",
    )


def _event(n: int) -> Event:
    return Event(kind=EventKind.OWN_RELEASED, reason="released", object="arm1", user="s01", data={"n": n})
