"""A sim whose clock is 5 s off the user's (another machine, no NTP) changes nothing the API decides:
freshness is judged by arrival here, never by comparing the sim's header wall_ns with ours.

The "sim" is a real Zenoh peer on the test's router whose headers are stamped with a shifted clock; it
answers joint and path commands the way the sim peer does (state at the target, or a reject event). Like a
live sim, it sends each robot's first state once a handle listens for it (a handle waits up to a second for
one: a sim that never sent it made each test wait that second out, twice)."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

import user_peer
from fabric import keys
from fabric.interfaces import Command, Event, Header, JointState, Path, Pose
from robofabric.testing import client_config
from user_peer.api import Arm, Base, World
from user_peer.services import RobotEntry

JOINTS = tuple(f"joint_{i}" for i in range(1, 7))


class SkewedSim:
    """Answers commands with state or rejections, every header stamped ``skew_s`` off this machine's clock."""

    def __init__(self, fab, skew_s: float) -> None:
        self.fab = fab
        self.skew_ns = int(skew_s * 1e9)
        self.reject = False
        self._seq = 0
        self._lock = threading.Lock()
        fab.subscribe(keys.robot_cmd_all(fab.world), self._on_command, expected=Command)

    def send_first_states(self, timeout: float = 10.0) -> threading.Thread:
        """Once a subscriber of each robot's state is known, its first state (at rest, at the origin): the
        state a live sim streams, and a handle waits for when it is made. Returns the thread that sends them."""

        def send() -> None:
            w = self.fab.world
            if self.fab.wait_matching(keys.robot_joints(w, "arm1"), timeout):
                self.fab.publish(
                    keys.robot_joints(w, "arm1"), JointState(JOINTS, np.zeros(6), np.zeros(6), self.header())
                )
            if self.fab.wait_matching(keys.robot_pose(w, "base1"), timeout):
                self.fab.publish(keys.robot_pose(w, "base1"), Pose([0.0, 0.0, 0.0], header=self.header()))

        thread = threading.Thread(target=send, name="skewed-sim-first-states", daemon=True)
        thread.start()
        return thread

    def _on_command(self, key: str, cmd: Command) -> None:
        p = keys.parse(key)
        if (p.subject, p.leaf) == ("arm1", "joints"):
            self._on_joints(key, cmd)
        elif (p.subject, p.leaf) == ("base1", "path"):
            self._on_path(key, cmd)

    def header(self) -> Header:
        with self._lock:
            self._seq += 1
            return Header(stamp=0.0, wall_ns=time.time_ns() + self.skew_ns, seq=self._seq, source="skewed-sim")

    def _refuse(self, robot: str, cmd: Command) -> None:
        ev = Event(
            kind="reject",
            reason=f"{robot} is owned by zoe, not {cmd.user}",
            object=robot,
            user=cmd.user,
            severity="warning",
            header=self.header(),
        )
        self.fab.publish(keys.event(self.fab.world, "reject", robot), ev)

    def _on_joints(self, key: str, cmd: Command) -> None:
        if self.reject:
            return self._refuse("arm1", cmd)
        q = np.asarray(cmd.body.q, dtype=float)
        self.fab.publish(keys.robot_joints(self.fab.world, "arm1"), JointState(JOINTS, q, np.zeros(6), self.header()))

    def _on_path(self, key: str, cmd: Command) -> None:
        if self.reject:
            return self._refuse("base1", cmd)
        end = [float(cmd.body.x[-1]), float(cmd.body.y[-1]), 0.0]
        self.fab.publish(keys.robot_pose(self.fab.world, "base1"), Pose(end, header=self.header()))


@pytest.fixture(params=[-5.0, 5.0], ids=["sim-5s", "sim+5s"])
def skewed(request, world, router, connect):
    sim = SkewedSim(connect("sim", "skewed-sim"), request.param)
    w = World(client_config(world, router[1]), "alice", timeout=2.0)
    first = sim.send_first_states()
    lim = (-3.0,) * 6, (3.0,) * 6
    arm = Arm(w, RobotEntry("arm1", "meca500", "arm", JOINTS, *lim, (1.0,) * 6))
    base = Base(w, RobotEntry("base1", "reeman", "mobile"))
    first.join(timeout=10.0)
    try:
        yield sim, w, arm, base
    finally:
        w.close()


def _eventually(fn, timeout: float = 10.0):
    """Retry while the peers' subscriptions are still being matched across the router (first call only)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return fn()
        except user_peer.Timeout:
            if time.monotonic() > deadline:
                raise


def test_joint_moves_finish_and_refusals_arrive_whatever_the_sims_clock(skewed):
    sim, w, arm, _ = skewed
    target = np.array([0.1, 0.2, -0.3, 0.0, 0.4, 0.0])
    # sim 5 s behind: its answer looks older than the command by the header; it still counts
    q = _eventually(lambda: arm.move_joints(target, tol=1e-6, timeout=1.0))
    assert np.allclose(q, target)
    # a refusal is raised at once (not ignored as "old" until the move times out)
    sim.reject = True
    t0 = time.monotonic()
    with pytest.raises(user_peer.NotOwner, match="owned by zoe"):
        arm.move_joints(-target, timeout=30.0)
    assert time.monotonic() - t0 < 15.0, "the refusal was ignored until the move's timeout"
    # sim 5 s ahead: that earlier refusal now looks newer than the next command; it must not refuse it
    sim.reject = False
    q = arm.move_joints(-target, tol=1e-6, timeout=5.0)
    assert np.allclose(q, -target)


def test_path_following_ends_on_a_pose_that_arrived_after_the_command(skewed):
    sim, w, _, base = skewed
    n = 5
    path = Path(np.linspace(0, 1, n), np.linspace(0, 2, n), np.zeros(n))
    xy = _eventually(lambda: base.follow(path, tol=0.05, timeout=1.0))
    assert math.hypot(xy[0] - 1.0, xy[1] - 2.0) < 1e-9
    # a pose from before the command (even one stamped 5 s "later" by the sim's clock) does not end it
    mark = w.latest.mark()
    assert w.latest.get_after(keys.robot_pose(w.name, "base1"), mark) is None
    sim.reject = True
    with pytest.raises(user_peer.NotOwner):
        base.follow(Path(np.array([5.0, 6.0]), np.array([5.0, 6.0]), np.zeros(2)), timeout=30.0)


def test_ages_are_local_whatever_the_sims_clock(skewed):
    """repr and Robot.age measure time since arrival here: a message that just arrived is fresh."""
    sim, w, arm, _ = skewed
    _eventually(lambda: arm.move_joints(np.zeros(6), tol=1e-6, timeout=1.0))
    age = arm.age("joints")
    assert age is not None and 0.0 <= age < 2.0, age
    assert "joints" in repr(arm) and "ago" in repr(arm)
