"""A primary sim whose cable is pulled stops its robots, and takes commands again when it hears again.

What a primary simulates while nobody hears it is lost when a standby takes the world over (the soak saw an arm's
joints jump 0.356 rad across such a take-over), and it may not drive a robot for an owner it cannot hear. Here the
sim is alone (no standby: it stays the primary across the cut), alice on her own host sets its arm on a slow, long
motion, and the sim's cable is pulled for a few seconds: the sim must say it hears no one and stop the arm where it
is, far from alice's target; plugged back in, it says it hears again, the arm is still where it stopped (the motion
was not resumed behind alice's back), and alice's next command moves it.
"""

from __future__ import annotations

import pytest

from robofabric.lab import Lab
from robofabric.testing import wait_until

pytestmark = [pytest.mark.lab, pytest.mark.slow]

LEASE = 2.0  # the fabric's transport lease (lease_ms default)

JOIN = """
import numpy as np, user_peer
w = user_peer.connect(world="demo", connect=["{router}"], user="alice", timeout=10.0)
assert w.wait_world(timeout=120), "the world never served"
arm = w.robot("arm1")
arm.request(timeout=10.0)
arm.wait_for("joints", timeout=30.0)
far = np.radians([120.0, 60.0, -60.0, 150.0, 80.0, 150.0])
arm.move_joints(far, wait=False, speed_scale=0.05)
True
"""

STATE = "js = arm.latest('joints'); (np.abs(np.asarray(js.q) - far).max(), np.abs(np.asarray(js.dq)).max(), arm.age('joints'))"


def test_a_primary_cut_off_stops_its_robots_and_takes_commands_again_when_it_hears_again(lab: Lab):
    router_host, sa, ah = lab.add_host("router"), lab.add_host("sa"), lab.add_host("alice")
    ep = router_host.endpoint()
    router = router_host.start(["router", "--listen", ep], name="router")
    wait_until(lambda: "listening" in router.output() or not router.alive(), timeout=120, what="router listening")
    sim = sa.start(["sim", "--scene", "arm_cell", "--world", "demo", "--connect", ep, "--id", "sim-a"], name="sim-a")
    wait_until(
        lambda: "Ctrl-C to stop" in sim.output() or not sim.alive(),
        timeout=120,
        what="the sim",
        seen=lambda: sim.output()[-800:],
    )
    alice = ah.python(name="alice")
    alice.call(JOIN.format(router=ep), timeout=240)
    state: list = []

    def moving() -> bool:
        state[:] = alice.call(STATE)
        return state[1] > 0.02

    wait_until(moving, timeout=60, what="the arm moving toward alice's far target", seen=lambda: state)

    lab.cut(sa)
    try:
        wait_until(
            lambda: "hears no one" in sim.output(),
            timeout=LEASE + 30,
            what="the cut-off sim stopping its robots",
            seen=lambda: sim.output()[-1500:],
        )
    finally:
        lab.restore(sa)
    wait_until(
        lambda: "hears again" in sim.output(),
        timeout=60,
        what="the sim hearing again",
        seen=lambda: sim.output()[-1500:],
    )

    def fresh_and_still() -> bool:
        state[:] = alice.call(STATE)
        return state[2] is not None and state[2] < 0.5 and state[1] < 1e-3

    wait_until(fresh_and_still, timeout=60, what="fresh joints of a still arm after the cut", seen=lambda: state)
    assert state[0] > 0.2, f"the arm went on to alice's target while its sim heard no one: {state}"
    assert "commands are refused" in sim.output()

    # the sim takes alice's commands again: the arm reaches a target she sends now
    reached = alice.call("arm.move_joints(np.radians([10.0, 0.0, 0.0, 0.0, 0.0, 0.0]), timeout=60.0); True", timeout=90)
    assert reached is True
    assert sim.alive(), sim.output()[-2000:]
