"""A hiccup costs nobody a command: a sim paused (SIGSTOP) 3 s, three times in a row (and once 1.5 s), while two
students move their arms in a loop with ``wait=True``: not one move fails. Then the same with a CPU hog (a busy-loop child
process) beside the sim, so that it is starved as well as paused.

The sim (a real ``robofabric sim`` process, alone in its world) was late, not cut off: it proves its link (its
router answers) and takes commands again at once, and a command that met it holding its robots is ridden out by
the client (sent again, the same command id under the same epoch) within its timeout (:mod:`user_peer.pause`,
:mod:`sim_peer.replica.deaf_stop`)."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

import numpy as np
import pytest

from robofabric.testing import client_config, robofabric_cmd, wait_until
from user_peer.api import World

pytestmark = pytest.mark.slow

PAUSE_S = 3.0
PAUSES = 3
LATE_S = 1.5
"""A last, shorter pause: longer than half the transport lease (the sim's heartbeat sees it), shorter than the lease
(the router keeps the sim's link): the sim was late, not cut off, and says so."""
TARGETS = (np.radians([25.0, 10.0, -15.0, 0.0, 20.0, 0.0]), np.radians([-25.0, -5.0, 10.0, 0.0, -20.0, 0.0]))


class Student:
    """One student moving her arm between two targets with ``wait=True`` until told to stop; every failed move kept."""

    def __init__(self, world: World, robot: str) -> None:
        self.arm = world.robot(robot)
        self.moves = 0
        self.failures: list[str] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, name=f"student-{robot}", daemon=True)

    def start(self) -> "Student":
        self.arm.wait_for("joints", timeout=30.0)
        self.arm.request(timeout=10.0)
        self.thread.start()
        return self

    def _loop(self) -> None:
        i = 0
        while not self.stop.is_set():
            try:
                self.arm.move_joints(TARGETS[i % 2], wait=True, timeout=20.0, tol=2e-3)
                self.moves += 1
            except Exception as exc:  # every failure is the test's finding
                self.failures.append(f"{type(exc).__name__}: {exc}")
            i += 1

    def end(self) -> None:
        self.stop.set()
        self.thread.join(30.0)


def _run(world: str, router, procs, *, hog: bool) -> None:
    ep = f"tcp/127.0.0.1:{router[1]}"
    sim = procs.start(
        robofabric_cmd(
            "sim",
            "--scene",
            "arm_cell",
            "--robot",
            "meca500:arm2@1.0,0.0",
            "--world",
            world,
            "--connect",
            ep,
            "--id",
            "sim-a",
        ),
        name="sim",
    )
    if hog:  # a busy loop beside the sim (bounded: ended by pid at the test's end)
        procs.start([sys.executable, "-c", "while True: pass"], name="hog")
    worlds = [World(client_config(world, router[1]), u, timeout=10.0, join_timeout=120.0) for u in ("alice", "bob")]
    students: list[Student] = []
    try:
        students = [Student(worlds[0], "arm1").start(), Student(worlds[1], "arm2").start()]
        wait_until(
            lambda: all(s.moves >= 2 for s in students),
            timeout=120,
            what="two moves each before the pauses",
            seen=lambda: [(s.moves, s.failures[-1:]) for s in students],
        )
        for pause in (PAUSE_S,) * PAUSES + (LATE_S,):
            os.kill(sim.pid, signal.SIGSTOP)
            try:
                time.sleep(pause)  # the stimulus: a pause of this length (nothing is waited for here)
            finally:
                os.kill(sim.pid, signal.SIGCONT)
            done = [s.moves for s in students]
            wait_until(
                lambda: all(s.moves >= d + 2 for s, d in zip(students, done)),
                timeout=90,
                what="two more moves each after the pause",
                seen=lambda: ([(s.moves, s.failures[-1:]) for s in students], procs.output(sim)[-1500:]),
            )
    finally:
        for s in students:
            s.end()
        for w in worlds:
            w.close()
    failures = [f for s in students for f in s.failures]
    assert not failures, (failures, procs.output(sim)[-3000:])
    out = procs.output(sim)
    # the log says which case it was: past the lease the router dropped the sim's link (cut off, then back); the
    # short pause left it linked: late, its router answering at once, nothing held
    assert out.count("hears again") >= PAUSES - 1, out[-3000:]
    assert "was late" in out, out[-3000:]


def test_three_pauses_fail_no_waited_move(world, router, procs):
    _run(world, router, procs, hog=False)


def test_three_pauses_beside_a_cpu_hog_fail_no_waited_move(world, router, procs):
    _run(world, router, procs, hog=True)
