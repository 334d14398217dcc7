"""A standby does not take the world over from a leader it still hears, whatever the liveliness view says: a
leader's token can reach a sim late (its own link just back after a pause past the lease, a router restarted),
and a take-over then serves a world that stops where the standby's state does while the leader serves on. Once
the leader falls silent, the same view takes over."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import JointState
from fabric.session import Fabric
from robofabric.testing import client_config, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow


def _speak(leader: Fabric, world: str, stop: threading.Event, said: list[int]) -> None:
    """The leader's joints stream, stamped with its term, until ``stop``; ``said[0]`` counts the samples."""
    key = keys.robot_joints(world, "arm1")
    names = tuple(f"joint_{i}" for i in range(1, 7))
    while not stop.wait(0.02):
        leader.publish(key, JointState(names, np.zeros(6), np.zeros(6), leader.header(key)))
        said[0] += 1


def test_a_standby_waits_for_a_leader_it_hears_whose_token_is_missing(world, router, connect, procs):
    port = router[1]
    # a leader whose token this standby never sees: its streams are all it has of it
    leader = Fabric(client_config(world, port), kind="sim", peer_id="sim-a", token=False)
    leader.assume_term(1, ("arm1", "base1"))
    stop, said = threading.Event(), [0]
    speaker = threading.Thread(target=_speak, args=(leader, world, stop, said), daemon=True)
    speaker.start()
    try:
        standby = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", f"tcp/127.0.0.1:{port}",
                                             "--id", "sim-b", "--standby"), name="sim-b")
        wait_until(lambda: "following sim-a (term 1)" in procs.output(standby), timeout=90, what="the standby follows sim-a",
                   seen=lambda: procs.output(standby)[-1500:])
        # another sim's token comes and goes: the standby looks at the live sims, sim-a's token is not among them
        passer = connect("sim", "sim-z")
        wait_until(lambda: ("sim", "sim-z") in passer.live_peers("sim"), timeout=20, what="sim-z's token")
        passer.close()
        wait_until(lambda: "still heard" in procs.output(standby), timeout=30, what="the standby waiting on an audible leader",
                   seen=lambda: procs.output(standby)[-1500:])
        until = said[0] + 100  # two seconds of the leader speaking, a lease and more
        wait_until(lambda: "took over" in procs.output(standby) or said[0] >= until, timeout=60, what="the leader speaking on")
        assert "took over" not in procs.output(standby), procs.output(standby)[-1500:]
    finally:
        stop.set()
        speaker.join(5.0)
    # silent now: the same view takes the world over
    wait_until(lambda: "took over the world with term 2" in procs.output(standby), timeout=30, what="the take-over once silent",
               seen=lambda: procs.output(standby)[-1500:])
    leader.close()
