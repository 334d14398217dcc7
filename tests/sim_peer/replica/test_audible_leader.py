"""A primary that steps down for a higher term does not take the world back while it still hears the new leader,
whatever its view of the tokens says: after a pause past the lease its session can see the leader's token seconds
late, and a take-over then serves a world that stops where its own state does, while the leader serves on (the soak
saw epochs go back). Once the leader falls silent, the same view takes over."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import JointState
from fabric.session import Fabric
from robofabric.testing import SimRoles, client_config, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow


def _speak(leader: Fabric, world: str, stop: threading.Event, said: list[int]) -> None:
    """The leader's joints stream, stamped with its term, until ``stop``; ``said[0]`` counts the samples."""
    key = keys.robot_joints(world, "arm1")
    names = tuple(f"joint_{i}" for i in range(1, 7))
    while not stop.wait(0.02):
        leader.publish(key, JointState(names, np.zeros(6), np.zeros(6), leader.header(key)))
        said[0] += 1


def test_a_primary_that_steps_down_waits_for_a_leader_it_hears_whose_token_is_missing(world, router, connect, procs):
    port = router[1]
    roles = SimRoles(connect("tool", "roles"))  # the roles sim-b shows (its role token)
    sim = procs.start(
        robofabric_cmd(
            "sim", "--scene", "combined", "--world", world, "--connect", f"tcp/127.0.0.1:{port}", "--id", "sim-b"
        ),
        name="sim-b",
    )
    roles.wait("sim-b", "primary", term=1, timeout=90, seen=lambda: procs.output(sim)[-1500:])
    # a leader with a higher term whose token this sim never sees: its streams are all it has of it
    leader = Fabric(client_config(world, port), kind="sim", peer_id="sim-a", token=False)
    leader.assume_term(2, ("arm1", "base1"))
    stop, said = threading.Event(), [0]
    speaker = threading.Thread(target=_speak, args=(leader, world, stop, said), daemon=True)
    speaker.start()
    try:
        roles.wait("sim-b", "standby", term=2, leader="sim-a", timeout=60, seen=lambda: procs.output(sim)[-1500:])
        # its new view of the live sims (after a lease's wait for sim-a's token) lacks sim-a: heard, it is not gone
        wait_until(
            lambda: "still heard" in procs.output(sim) or roles.ever("sim-b", "primary", 3),
            timeout=30,
            what="the standby's look at the live sims",
            seen=lambda: procs.output(sim)[-1500:],
        )
        assert "still heard" in procs.output(sim), procs.output(sim)[-1500:]
        until = said[0] + 150  # three seconds of the leader speaking: past a lease
        wait_until(
            lambda: roles.ever("sim-b", "primary", 3) or said[0] >= until, timeout=60, what="the leader speaking on"
        )
        assert not roles.ever("sim-b", "primary", 3) and roles.role("sim-b") == "standby", procs.output(sim)[-1500:]
    finally:
        stop.set()
        speaker.join(5.0)
    # silent now: the same view takes the world over
    roles.wait("sim-b", "primary", term=3, timeout=30, seen=lambda: procs.output(sim)[-1500:])
    leader.close()
