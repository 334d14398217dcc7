"""A subscription with history (fabric/history.py) loses and reorders nothing live, and gives a late joiner
each latched key's latest value once, even where samples arrive out of timestamp order across one session's
publishers (zenoh's advanced subscriber dropped those: 1,743 of 1,820 poses on robot/**)."""

from __future__ import annotations

import threading
from collections import defaultdict

import numpy as np

from fabric import keys
from fabric.interfaces import Header, Pose
from robofabric.testing import wait_until

N = 300


def _pose(x: float, seq: int) -> Pose:
    return Pose(np.array([x, 0.0, 0.0]), np.array([1.0, 0.0, 0.0, 0.0]), header=Header.now(seq=seq, source="pub"))


def test_history_delivers_every_live_sample_of_every_publisher_and_each_latest_value_once(world, connect):
    pub = connect("sim", "pub")
    goal = keys.object_pose(world, "goal", "alice")
    for x in (1.0, 2.0, 3.0):  # only the last matters to a late joiner
        pub.publish(goal, _pose(x, 0))
    got: dict[str, list[int]] = defaultdict(list)
    goals: list[float] = []
    lock = threading.Lock()

    def on(key: str, msg: Pose) -> None:
        with lock:
            if key == goal:
                goals.append(float(msg.position[0]))
            else:
                got[key].append(msg.header.seq)

    late = connect("viewer", "late")
    late.subscribe(keys.world_all(world), on, history=True)
    wait_until(lambda: goals, what="the latched goal", seen=lambda: goals)
    streams = [keys.robot_pose(world, f"base{i}") for i in range(4)]
    for key in streams:
        wait_until(lambda key=key: pub.wait_matching(key, 0.1), what="the subscription known to the publisher")

    def publish(key: str) -> None:  # one thread per stream, one session: timestamps interleave across keys
        for seq in range(N):
            pub.publish(key, _pose(0.0, seq))

    threads = [threading.Thread(target=publish, args=(k,)) for k in streams]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    wait_until(
        lambda: all(len(got[k]) >= N for k in streams),
        timeout=30,
        what="every pose",
        seen=lambda: {k: len(v) for k, v in got.items()},
    )
    for key in streams:
        assert got[key] == list(range(N)), (key, len(got[key]))  # all of them, in the order sent
    assert goals == [3.0]  # the latest value, once
    pub.publish(goal, _pose(4.0, 1))
    wait_until(lambda: goals[-1:] == [4.0], what="a live goal after the history")
    assert goals == [3.0, 4.0]
