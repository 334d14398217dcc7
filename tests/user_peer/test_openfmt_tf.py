"""One transform tree in the Foxglove and ROS 2 exports, read back with the third-party decoders.

A world's arm publishes its joints and, with them, its flange as a world pose on ``robot/ID/pose``;
a mobile base publishes its pose. The exports must give every frame one parent and one source, by REP 105's
names rooted at ``map`` (``map -> base1/odom -> base1/base_link``; the arm's URDF links under ``arm1/``, each in
its parent link's frame, robot_state_publisher's tree, the flange the URDF's link from the joints, never a
second source from the pose), keep the arm's base bolted down (the same transform every time), and never let
a frame's stamps go back (a late sample, 7 ms older than the last one, is dropped rather than written after
the newer one). Decoded with
``mcap-protobuf-support``'s and ``mcap-ros2-support``'s decoders, not with the writers' classes.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoders
from mcap_ros2.decoder import DecoderFactory as Ros2Decoders

import robots
from fabric.codec import encode
from fabric.interfaces import Header, JointState, Pose
from fabric.recording import McapSink
from user_peer.openfmt import export_recording

W = "demo"
T0 = 1_760_000_000_000_000_000
N = 40
FLANGE = np.array([3.19, 0.0, 1.058])
LATE = 7_000_000  # ns: how far the late samples' stamps go back


def _quat_wxyz(yaw: float, pitch: float) -> np.ndarray:
    """A rotation about z then y, as (w, x, y, z)."""
    cz, sz, cy, sy = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    return np.array([cz * cy, -sz * sy, cz * sy, sz * cy])


def _messages() -> list[tuple[str, int, object]]:
    names = robots.load("meca500").joint_names
    out: list[tuple[str, int, object]] = []
    for i in range(N):
        t = T0 + i * 10_000_000
        h = Header(i * 0.01, t, i, "sim-1")
        q = np.array([0.05 * i, -0.2, 0.3, 0.0, 0.5, -0.6])
        # the flange pose goes out with the joints; the recorder may log it first
        out.append(
            (
                f"rf/{W}/robot/arm1/pose",
                t + 1,
                Pose(FLANGE + [0.0, 0.001 * i, 0.0], _quat_wxyz(0.02 * i, 0.3), header=h),
            )
        )
        out.append((f"rf/{W}/robot/arm1/joints", t + 2, JointState(names, q, q * 0.0, h)))
        out.append((f"rf/{W}/robot/base1/pose", t + 3, Pose(np.array([0.01 * i, 0.0, 0.0]), header=h)))
        if i == N // 2:  # late samples: stamped 7 ms before the last ones written for these frames (both clocks)
            late = Header(i * 0.01 - LATE / 1e9, t - LATE, i, "sim-1")
            out.append((f"rf/{W}/robot/arm1/joints", t + 4, JointState(names, q + 0.3, q * 0.0, late)))
            out.append((f"rf/{W}/robot/arm1/pose", t + 5, Pose(FLANGE - 0.5, header=late)))
            out.append((f"rf/{W}/robot/base1/pose", t + 6, Pose(np.array([-5.0, 0.0, 0.0]), header=late)))
    return out


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("tf") / "src.mcap"
    with McapSink(path) as sink:
        for key, t, msg in _messages():
            sink.write(key, encode(msg), t)
    return path


def _rot(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _transforms(path: Path, fmt: str) -> tuple[list[tuple[str, str, int, tuple, tuple]], list[int]]:
    """(parent, child, stamp ns, translation, rotation xyzw) of every /tf transform in file order, and /tf's publish times."""
    decoders = [ProtobufDecoders()] if fmt == "foxglove" else [Ros2Decoders()]
    tfs, pubs = [], []
    with open(path, "rb") as f:
        for _schema, _channel, message, m in make_reader(f, decoder_factories=decoders).iter_decoded_messages(
            topics=["/tf"]
        ):
            pubs.append(message.publish_time)
            for t in m.transforms:
                if fmt == "foxglove":
                    parent, child, stamp = (
                        t.parent_frame_id,
                        t.child_frame_id,
                        t.timestamp.seconds * 10**9 + t.timestamp.nanos,
                    )
                    tr, rot = t.translation, t.rotation
                else:
                    parent, child = t.header.frame_id, t.child_frame_id
                    stamp = t.header.stamp.sec * 10**9 + t.header.stamp.nanosec
                    tr, rot = t.transform.translation, t.transform.rotation
                tfs.append((parent, child, stamp, (tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w)))
    return tfs, pubs


@pytest.mark.parametrize("fmt", ["foxglove", "ros2"])
def test_export_has_one_transform_tree_a_bolted_base_and_monotonic_stamps(recording, tmp_path, fmt):
    out = tmp_path / f"{fmt}.mcap"
    export_recording(recording, out, fmt, scene="combined")
    tfs, pubs = _transforms(out, fmt)

    parents: dict[str, set[str]] = defaultdict(set)
    stamps: dict[str, list[int]] = defaultdict(list)
    by_child: dict[str, list[tuple]] = defaultdict(list)
    for parent, child, stamp, tr, rot in tfs:
        parents[child].add(parent)
        stamps[child].append(stamp)
        by_child[child].append((tr, rot))
    assert {c: p for c, p in parents.items() if len(p) != 1} == {}, "a frame with more than one parent"
    for child in parents:  # every chain ends at map, without a cycle
        seen, f = set(), child
        while f != "map":
            assert f not in seen and f in parents, (child, f)
            seen.add(f)
            (f,) = parents[f]
    assert parents["arm1/base_link"] == {"map"} and parents["arm1/flange"] == {"arm1/link_6"}
    assert parents["base1/odom"] == {"map"} and parents["base1/base_link"] == {"base1/odom"}
    assert parents["arm1/link_6"] == {"arm1/link_5"} and parents["arm1/link_1"] == {"arm1/base_link"}
    for child, st in stamps.items():
        assert st == sorted(st), f"{child}'s stamps go back"
    assert pubs == sorted(pubs), "/tf's publish times go back"

    # The arm's base never moves: the scene's placement, every time, and never the flange.
    base = by_child["arm1/base_link"]
    assert len(base) == N and len(set(base)) == 1, set(base)
    (tr, rot) = base[0]
    assert tr == pytest.approx((3.0, 0.0, 0.75)) and rot == pytest.approx((0.0, 0.0, 0.0, 1.0))
    # The late samples were dropped, not written after newer ones.
    assert (
        len(by_child["arm1/flange"]) == N
        and len(by_child["base1/base_link"]) == N
        and len(by_child["arm1/link_1"]) == N
    )
    assert all(t[0] > -1.0 for t, _r in by_child["base1/base_link"])

    # The flange, composed link by link up to map, is where the URDF's kinematics put it for those joints.
    model = pin.buildModelFromUrdf(str(robots.load("meca500").urdf_path))
    data, flange = model.createData(), model.getFrameId("flange")
    src = [m for k, _t, m in _messages() if k.endswith("arm1/joints") and m.q[1] == -0.2]  # not the late one
    chain = ["arm1/flange"]
    while chain[-1] != "map":
        chain.append(next(iter(parents[chain[-1]])))
    for i, msg in enumerate(src):
        r, t = np.eye(3), np.zeros(3)
        for child in chain[:-1]:  # world <- ... <- flange: T = T_parent(child) * T
            tr, rot = by_child[child][i if len(by_child[child]) == N else 0]
            t = _rot(*rot) @ t + np.array(tr)
            r = _rot(*rot) @ r
        pin.framesForwardKinematics(model, data, np.asarray(msg.q, dtype=float))
        rb, tb = _rot(*base[0][1]), np.array(base[0][0])
        assert t == pytest.approx(rb @ data.oMf[flange].translation + tb, abs=1e-9)
        assert r == pytest.approx(rb @ data.oMf[flange].rotation, abs=1e-9)
