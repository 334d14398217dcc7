"""A replicated sim (``run_replicated``, what ``robofabric sim`` runs) trims its heap (fabric.heap) for as long as it
runs: what zenoh's threads free through hours of faults goes back to the system."""

from __future__ import annotations

import threading

import pytest

from robofabric.testing import client, wait_until
from sim_peer.replica.replica_host import run_replicated
from sim_peer.physics.world import SimWorld


def _trimming() -> bool:
    return any(t.name == "heap-trim" and t.is_alive() for t in threading.enumerate())


@pytest.mark.slow  # a router and a sim: seconds
def test_a_replicated_sim_trims_its_heap_while_it_runs(world, router):
    from fabric.gate import OpenGate

    assert not _trimming()
    stop = threading.Event()
    hosts: list = []
    thread = threading.Thread(
        target=lambda: hosts.append(
            run_replicated(
                lambda: client(world, router[1], kind="sim", peer_id="sim-a"),
                lambda: SimWorld("combined", seed=1),
                lambda f, w, r, objects=True: OpenGate(),
                stop,
                standby=False,
            )
        ),
        daemon=True,
    )
    thread.start()
    try:
        wait_until(_trimming, timeout=30, what="the sim's heap trimmer running")
    finally:
        stop.set()
        thread.join(30)
    assert not thread.is_alive() and hosts
    assert not _trimming()  # stopped with the sim
