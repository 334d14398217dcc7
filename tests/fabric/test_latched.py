"""Latched keys: a late joiner gets the latest scene object, map and path at once (zenoh.ext cache + history)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import JointState, OccupancyGrid, Path, Pose
from robofabric.testing import wait_until


@pytest.mark.parametrize(
    ("key", "latched"),
    [
        ("rf/w/object/goal/pose/by/alice", True),
        ("rf/w/map/map", True),
        ("rf/w/robot/base1/path", True),
        ("rf/w/robot/base1/pose", False),
        ("rf/w/robot/arm1/joints", False),
        ("rf/w/robot/base1/cmd/path/by/alice", False),  # a command is never replayed to a robot
        ("rf/w/own/arm1", False),  # replicas query the authority instead
        ("rf/w/event/own", False),
        ("not/a/key", False),
    ],
)
def test_which_keys_are_latched(key, latched):
    assert keys.is_latched(key) is latched


class Inbox:
    def __init__(self) -> None:
        self.got: list[tuple[str, object]] = []
        self._lock = threading.Lock()

    def __call__(self, key: str, msg: object) -> None:
        with self._lock:
            self.got.append((key, msg))

    def keys(self) -> list[str]:
        with self._lock:
            return [k for k, _ in self.got]


def test_a_late_subscriber_gets_the_latest_latched_values_then_live_ones(world, connect):
    pub = connect("user", "setter")
    goal, grid, path, joints = (
        keys.object_pose(world, "goal", "alice"),
        keys.map_key(world, "map"),
        keys.robot_path(world, "base1"),
        keys.robot_joints(world, "arm1"),
    )
    # a witness of the first joints sample: once it has it, the router has routed that sample, and the late
    # subscriber below cannot get it as a live one (on a busy machine it arrived after the late subscription)
    witness = Inbox()
    connect("tool", "witness").subscribe(joints, witness)
    wait_until(lambda: pub.wait_matching(joints, 0.1), what="the witness's subscription known to the publisher")
    for x in (1.0, 2.0, 3.0):  # only the last goal matters to a late joiner
        pub.publish(goal, Pose(np.array([x, 0.0, 0.0]), np.array([1.0, 0.0, 0.0, 0.0]), header=pub.header(goal)))
    pub.publish(grid, OccupancyGrid(0.05, np.zeros(3), np.zeros((40, 30), np.uint8), header=pub.header(grid)))
    pub.publish(path, Path(np.arange(3.0), np.zeros(3), np.zeros(3), header=pub.header(path)))
    pub.publish(joints, JointState(["j1"], np.zeros(1), np.zeros(1), header=pub.header(joints)))
    wait_until(lambda: joints in witness.keys(), what="the first joints routed")

    late = connect("viewer", "late")
    plain, hist = Inbox(), Inbox()
    late.subscribe(keys.world_all(world), plain)
    late.subscribe(keys.world_all(world), hist, history=True)
    wait_until(lambda: {goal, grid, path} <= set(hist.keys()), what="the latched values", seen=hist.keys)
    assert sorted(hist.keys()) == sorted([goal, grid, path]), hist.keys()  # each once; joints are not latched
    assert dict(hist.got)[goal].position[0] == 3.0
    assert dict(hist.got)[grid].cells.shape == (40, 30)
    assert plain.keys() == []  # a plain subscriber only hears what comes after it

    pub.publish(joints, JointState(["j1"], np.ones(1), np.zeros(1), header=pub.header(joints)))
    wait_until(
        lambda: joints in hist.keys() and joints in plain.keys(),
        what="a live sample on both",
        seen=lambda: (hist.keys(), plain.keys()),
    )


def test_a_user_who_joins_late_sees_the_goal_and_the_map(world, router):
    from robofabric.testing import client_config
    from user_peer.api import World

    with World(client_config(world, router[1]), "early") as early:
        early.object("goal").set_pose([1.5, -0.5, 0.0], yaw=0.3)
        grid_key = keys.map_key(world, "map")
        early.fabric.publish(
            grid_key,
            OccupancyGrid(0.1, np.zeros(3), np.full((5, 5), 100, np.uint8), header=early.fabric.header(grid_key)),
        )
        with World(client_config(world, router[1]), "late") as late:
            got = wait_until(lambda: late.object("goal").pose, what="the goal set before joining")
            assert np.allclose(got.position, [1.5, -0.5, 0.0])
            wait_until(lambda: late.latest.get(grid_key) is not None, what="the map built before joining")


@pytest.mark.slow
def test_echo_prints_the_latest_latched_value_without_waiting_for_a_new_one(world, router, connect):
    import json
    import subprocess

    from robofabric.testing import robofabric_cmd

    pub = connect("user", "setter")
    goal = keys.object_pose(world, "goal", "alice")
    pub.publish(goal, Pose(np.array([4.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0, 0.0]), header=pub.header(goal)))
    out = subprocess.run(
        robofabric_cmd(
            "echo",
            "object/goal/pose/by/*",
            "--json",
            "--count",
            "1",
            "--world",
            world,
            "--connect",
            f"tcp/127.0.0.1:{router[1]}",
        ),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    line = json.loads(out.stdout.splitlines()[0])
    assert line["key"] == goal and line["message"]["position"] == [4.0, 1.0, 0.0]


def test_latched_values_block_streams_and_commands_drop(world, connect):
    import zenoh

    from fabric.publishers import declare_publisher

    fab = connect("tool", "qos")
    block, drop = zenoh.CongestionControl.BLOCK, zenoh.CongestionControl.DROP
    for key, want in (
        (keys.map_key(world, "map"), block),  # published once: a dropped map is never resent
        (keys.object_pose(world, "goal", "alice"), block),
        (
            keys.robot_cmd(world, "base1", "path", "alice"),
            drop,
        ),  # see docs/architecture.md: blocking commands stalled peers
        (keys.robot_joints(world, "arm1"), drop),  # the next sample replaces a lost one
    ):
        pub = declare_publisher(fab.session, key)
        try:
            assert pub.congestion_control == want, key
        finally:
            pub.undeclare()
