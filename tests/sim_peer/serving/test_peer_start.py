"""SimPeer.start: a peer whose physics thread is being started is not ``finished``.

``finished`` is what a replica host's run loop reads to end the sim (its --duration reached); a take-over starts
its new peer on a thread of its own while that loop looks, and a started-but-not-yet-running thread is not alive.
Read as finished, the sim that had just taken the world over stopped with 0 steps and exited 0 (the soak)."""

from __future__ import annotations

import threading

import pytest

from robofabric.testing import wait_until
from sim_peer.serving.peer import SimPeer
from sim_peer.physics.world import SimWorld

pytestmark = pytest.mark.slow  # a router and a sim session


def test_a_peer_whose_physics_is_starting_is_not_finished(connect, monkeypatch):
    peer = SimPeer(connect("sim", "sim-start"), SimWorld("combined", seed=1))
    seen: list[bool] = []
    real_start = threading.Thread.start

    def start(thread: threading.Thread) -> None:
        if thread.name == "sim-physics":
            seen.append(peer.finished)  # what a host's loop would read while the thread starts
        real_start(thread)

    monkeypatch.setattr(threading.Thread, "start", start)
    try:
        peer.start()
        assert seen == [False]
        assert not peer.finished
        wait_until(lambda: peer.counters["steps"] > 0, timeout=20, what="the peer stepping")
    finally:
        peer.close()
    assert peer.finished  # closed: its physics ended
