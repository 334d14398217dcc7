"""Whatever well-formed command arrives, on whatever key, the peer answers it or rejects it with a reason: never a crash.

The command handler runs against a stub fabric (no network) so hypothesis can try many sequences quickly; the
real Zenoh path is covered in test_peer.py.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
import pytest

from fabric import keys
from fabric.interfaces import Command, Event, Header, JointTarget, Path, Reset, Stop, Twist
from sim_peer.serving.peer import SimPeer
from sim_peer.physics.world import SimWorld

WORLD = SimWorld("combined")


class StubFabric:
    world = "fuzz"
    closed = False

    def __init__(self) -> None:
        self.events: list[Event] = []
        self.reports = self  # fabric.reports' should_report and emit, as the sim calls them

    def header(self, key: str, *, stamp: float = 0.0) -> Header:
        return Header(stamp=stamp)

    def should_report(self, key: str) -> int:
        return 0  # report everything: the fuzz counts events

    def emit(self, event: Event, *parts: str, limit: str | None = None) -> None:
        keys.event(self.world, *parts)  # the key must be buildable
        self.events.append(event)


finite = st.floats(-1e6, 1e6, allow_nan=False)
bodies = st.one_of(
    st.builds(lambda q, s: JointTarget(np.array(q), s), st.lists(finite, max_size=8), st.floats(1e-6, 1.0)),
    st.builds(Twist, finite, finite),
    st.integers(0, 30).flatmap(
        lambda n: st.builds(
            lambda x, y: Path(np.array(x), np.array(y), np.zeros(n)),
            st.lists(finite, min_size=n, max_size=n),
            st.lists(finite, min_size=n, max_size=n),
        )
    ),
    st.just(Stop()),
    st.just(Reset()),
)
commands = st.lists(
    st.tuples(
        st.sampled_from(["arm1", "base1", "ghost"]),
        st.sampled_from(["joints", "twist", "path", "stop", "reset"]),
        bodies,
    ),
    max_size=12,
)


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(commands)
def test_every_command_is_accepted_or_rejected_with_a_reason(seq):
    WORLD.reset()
    fab = StubFabric()
    peer = SimPeer(fab, WORLD)  # type: ignore[arg-type]
    for robot, name, body in seq:
        peer.apply_command(keys.robot_cmd("fuzz", robot, name, "u"), Command("u", 0, body))
        WORLD.step(5)
    c = peer.counters
    assert c["commands"] == len(seq) == c["accepted"] + c["rejected"]
    rejects = [e for e in fab.events if e.kind == "reject"]
    assert len(rejects) == c["rejected"] and all(e.reason for e in rejects)
    for r in WORLD.robots.values():  # the world is still sane
        names, q, dq = r.joint_state()
        assert np.isfinite(q).all() and np.isfinite(dq).all()
    arm = WORLD.robot("arm1").ctrl
    assert np.all(arm.q >= arm.lower) and np.all(arm.q <= arm.upper)
    base = WORLD.robot("base1").ctrl
    assert abs(base.v) <= base.spec.max_speed + 1e-9 and math.isfinite(base.x + base.y + base.yaw)
