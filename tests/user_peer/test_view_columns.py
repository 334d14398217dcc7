"""Columnar drawing (user_peer.rerun_columns) and the live viewer's never-behind rule (user_peer.viewer)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

import robots
from fabric import keys
from fabric.interfaces import Header, JointState, Pose
from robofabric.testing import client_config
from user_peer.arm_geometry import ArmGeometry
from user_peer.catalog import placement_xyz_yaw
from user_peer.geometry import compose, quat_mul_xyzw
from user_peer.rerun_columns import ArmChain, quat_mul, quat_rotate
from user_peer.viewer import Viewer, ViewerOptions


def test_arm_chain_is_pinocchios_fk_for_a_window_of_joint_states():
    """The chain draws a whole window at once with numpy; every joint origin is where Pinocchio puts it."""
    arm = ArmGeometry(robots.load("meca500").urdf_path)
    chain = ArmChain(arm)
    assert chain.supported and chain.nq == 6
    base = placement_xyz_yaw(1.0, -2.0, 0.1, 0.7)
    q = np.random.default_rng(1).uniform(-2.5, 2.5, (50, 6))
    origins = chain.origins(q, base)
    assert origins.shape == (50, 7, 3)
    for i in range(50):
        ref = np.array([compose(base, pl)[0] for pl in arm.fk(q[i])])
        assert np.allclose(origins[i], ref, atol=1e-9)
    # each joint's entity sits below its parent's: the link shapes hang below their joint
    assert chain.path("links", 2) == "links/joint_1/joint_2/joint_3"
    assert chain.path("links", -1) == "links"


def test_vectorised_quaternions_match_the_single_ones():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(20, 4)), rng.normal(size=(20, 4))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    ab = quat_mul(a, b)
    for i in range(20):
        assert np.allclose(ab[i], quat_mul_xyzw(a[i], b[i]))
    # a quarter turn about z takes x to y
    qz = np.array([0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)])
    assert np.allclose(quat_rotate(qz, np.array([1.0, 0.0, 0.0])), [0.0, 1.0, 0.0])


@pytest.fixture
def viewer(world, router, tmp_path):
    v = Viewer(
        client_config(world, router[1]),
        ViewerOptions(save=tmp_path / "v.rrd", max_hz=0, max_lag_s=0.5),
        peer_id="viewer-lag",
    )
    try:
        yield v
    finally:
        v.close()


def _js(i: int) -> JointState:
    return JointState(
        ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6"),
        np.full(6, 0.01 * i),
        np.zeros(6),
        Header(stamp=0.01 * (i + 1), seq=i),
    )


def test_a_viewer_behind_drops_the_oldest_per_stream_never_a_robots_last_state(viewer, world):
    """Samples that waited longer than max_lag_s when their window is drawn are dropped and counted, stream by
    stream; each stream's newest is drawn however old (the robot's last state)."""
    arm, base = keys.robot_joints(world, "arm1"), keys.robot_pose(world, "base1")
    for i in range(100):
        viewer.receive(arm, _js(i))
    for i in range(3):
        viewer.receive(base, Pose([0.1 * i, 0.0, 0.0], header=Header(stamp=0.01 * (i + 1), seq=i)))
    fresh = viewer.take()  # drawn at once: nothing is late
    assert len(fresh) == 103 and viewer.dropped == 0
    assert [t for t, _, _ in fresh] == sorted(t for t, _, _ in fresh)  # in arrival order across streams

    for i in range(100):
        viewer.receive(arm, _js(i))
    for i in range(3):
        viewer.receive(base, Pose([0.1 * i, 0.0, 0.0], header=Header(stamp=0.01 * (i + 1), seq=i)))
    late = viewer.take(now_ns=time.time_ns() + 2_000_000_000)  # the drawing thread came back 2 s later
    assert [(key, msg.header.seq) for _, key, msg in late] == [(arm, 99), (base, 2)] or [
        (key, msg.header.seq) for _, key, msg in late
    ] == [(base, 2), (arm, 99)]
    assert viewer.dropped == 99 + 2
    assert viewer.dropped_per_stream == {arm: 99, base: 2}


def test_a_stalled_viewer_keeps_at_most_queue_size_per_stream(world, router, tmp_path):
    v = Viewer(
        client_config(world, router[1]),
        ViewerOptions(save=tmp_path / "v.rrd", max_hz=0),
        peer_id="viewer-q",
        queue_size=10,
    )
    try:
        key = keys.robot_joints(world, "arm1")
        for i in range(25):
            v.receive(key, _js(i))
        assert v.dropped == 15
        assert [m.header.seq for _, _, m in v.take()] == list(range(15, 25))
    finally:
        v.close()


def test_view_refuses_a_window_or_lag_that_makes_no_sense(tmp_path, capsys):
    from robofabric.cli import main  # in-process: the same exit code and message as the command's

    for bad in (("--window", "0"), ("--window", "9"), ("--max-lag", "0")):
        rc = main(["view", *bad, "--save", str(tmp_path / "v.rrd")])
        err = capsys.readouterr().err
        assert rc == 2 and "--window must be in (0, 5] s and --max-lag positive" in err, (bad, rc, err)
