"""Exports to Foxglove's and ROS 2's MCAP: every message parses against its declared schema, values match the source.

The source is a fabric recording written with the recorder's own sink (``McapSink``) holding every
kind of stream a world has: an arm's joints, a mobile robot's pose, LIDAR scan and path, a map with
unknown cells, the IK target's pose, ownership records, events, commands and IK stream messages.
Foxglove's protobuf messages are parsed with the FileDescriptorSet the file itself declares (not
with the writer's classes), JSON messages are validated with ``jsonschema`` against the channel's
declared schema, and ROS 2 messages are decoded with ``mcap-ros2-support``'s decoder.
"""

from __future__ import annotations

import json
import math
import subprocess
from collections import Counter, defaultdict
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

import robots
from fabric import keys
from fabric.interfaces import (
    Command,
    Event,
    Header,
    IKStream,
    JointState,
    OccupancyGrid,
    OwnershipRecord,
    Path as FPath,
    Pose,
    Scan,
    Twist,
)
from fabric.codec import encode
from fabric.recording import McapSink
from robofabric.testing import robofabric_cmd
from user_peer.openfmt import export_recording

W = "demo"
T0 = 1_760_000_000_000_000_000
N = 30


def _grid() -> OccupancyGrid:
    cells = np.zeros((12, 20), dtype=np.uint8)
    cells[3, 5:9] = 100
    cells[7, 2] = 55
    cells[10:, :] = 255
    return OccupancyGrid(0.05, np.array([-1.0, -0.5, 0.0]), cells)


def source_messages() -> list[tuple[str, int, object]]:
    names = robots.load("meca500").joint_names
    out: list[tuple[str, int, object]] = []
    for i in range(N):
        t = T0 + i * 20_000_000
        h = Header(i * 0.02, t - 1000, i, "sim-1")
        q = np.array([0.1 * i, -0.2, 0.3, 0.05 * i, 0.5, -0.6])
        out.append((f"rf/{W}/robot/arm1/joints", t, JointState(names, q, q * 0.5, h)))
        yaw = 0.1 * i
        quat = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
        out.append((f"rf/{W}/robot/base1/pose", t + 1, Pose(np.array([0.05 * i, -0.02 * i, 0.0]), quat, header=h)))
        if i % 3 == 0:
            ranges = np.linspace(0.2, 7.5, 240) + 0.01 * i
            ranges[::17] = np.inf  # misses read range_max
            out.append(
                (
                    f"rf/{W}/robot/base1/scan",
                    t + 2,
                    Scan.from_ranges(
                        ranges, angle_min=-math.pi, angle_increment=2 * math.pi / 240, range_max=8.0, header=h
                    ),
                )
            )
        if i % 10 == 0:
            out.append((keys.object_pose(W, "target", "alice"), t + 3, Pose(np.array([3.1, 0.1 * i, 1.0]), header=h)))
            out.append(
                (
                    f"rf/{W}/own/arm1",
                    t + 4,
                    OwnershipRecord("arm1", owner="alice", epoch=i + 1, queue=("bob",), authority="sim-1", header=h),
                )
            )
            out.append(
                (
                    f"rf/{W}/event/ownership/arm1",
                    t + 5,
                    Event(
                        "granted",
                        reason="free",
                        object="arm1",
                        user="alice",
                        data={"epoch": i + 1, "queue": ["bob"]},
                        header=h,
                    ),
                )
            )
            out.append((keys.robot_cmd(W, "base1", "twist", "bob"), t + 6, Command("bob", 3, Twist(0.2, -0.1, h), h)))
            out.append(
                (
                    f"rf/{W}/robot/arm1/ik",
                    t + 7,
                    IKStream("arm1", "target", np.array([3.1, 0.0, 1.0]), True, "", q, q * 0.1, np.abs(q), 1.5, h),
                )
            )
    out.append((f"rf/{W}/map/map", T0 + 5, _grid()))
    x = np.linspace(0.0, 2.0, 9)
    out.append(
        (f"rf/{W}/robot/base1/path", T0 + 6, FPath(x, np.sin(x), np.cos(x), header=Header(0.0, T0, 0, "compute-1")))
    )
    return out


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("src") / "src.mcap"
    with McapSink(path) as sink:
        for key, t, msg in sorted(source_messages(), key=lambda x: x[1]):
            sink.write(key, encode(msg), t)
        sink.write(f"rf/{W}/event/blob", b"\x00not msgpack\xff", T0 + 10**9)
    return path


def _by_topic() -> dict[str, list[object]]:
    out: dict[str, list[object]] = defaultdict(list)
    for key, _t, msg in sorted(source_messages(), key=lambda x: x[1]):
        out[key].append(msg)
    return out


# --------------------------------------------------------------------------- Foxglove


def _proto_class(schema) -> type:
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def test_foxglove_export_every_message_parses_against_its_schema_and_matches(recording, tmp_path):
    out = tmp_path / "fox.mcap"
    stats = export_recording(recording, out, "foxglove", scene="combined")
    assert (stats.messages, stats.bad, stats.skipped) == (len(source_messages()), 0, 0) and set(stats.robots) == {
        "arm1",
        "base1",
    }, stats
    src = _by_topic()
    seen: dict[str, list] = defaultdict(list)
    schemas: dict[str, str] = {}
    classes: dict[int, type] = {}
    validators: dict[int, jsonschema.protocols.Validator] = {}
    count = 0
    with open(out, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            count += 1
            schemas[channel.topic] = schema.name
            if channel.message_encoding == "protobuf":
                assert schema.encoding == "protobuf"
                if schema.id not in classes:
                    classes[schema.id] = _proto_class(schema)
                m = classes[schema.id]()
                m.ParseFromString(message.data)
                assert m.SerializeToString() == message.data  # nothing unknown, nothing lost
                seen[channel.topic].append(m)
            else:
                assert channel.message_encoding == "json" and schema.encoding == "jsonschema", (channel, schema)
                if schema.id not in validators:
                    sch = json.loads(schema.data)
                    jsonschema.Draft202012Validator.check_schema(sch)
                    validators[schema.id] = jsonschema.Draft202012Validator(sch)
                doc = json.loads(message.data)
                errors = list(validators[schema.id].iter_errors(doc))
                assert not errors, (channel.topic, errors[0].message)
                seen[channel.topic].append(doc)
    assert count == stats.written
    k = f"/rf/{W}"
    assert schemas[f"{k}/robot/base1/scan"] == "foxglove.LaserScan"
    assert schemas[f"{k}/map/map"] == "foxglove.Grid"
    assert schemas[f"{k}/robot/base1/path"] == "foxglove.PosesInFrame"
    assert schemas["/tf"] == "foxglove.FrameTransforms" and schemas["/scene"] == "foxglove.SceneUpdate"
    assert schemas[f"{k}/object/target/pose/by/alice"] == "foxglove.PoseInFrame"
    for topic in (
        "robot/arm1/joints",
        "own/arm1",
        "event/ownership/arm1",
        "robot/base1/cmd/twist/by/bob",
        "robot/arm1/ik",
    ):
        assert schemas[f"{k}/{topic}"].startswith("robofabric."), (topic, schemas[f"{k}/{topic}"])

    # Values: joints (plottable by name), scans, map cells, path, transforms of both robots.
    joints = seen[f"{k}/robot/arm1/joints"]
    assert len(joints) == N
    for doc, msg in zip(joints, src[f"rf/{W}/robot/arm1/joints"]):
        assert doc["q"] == pytest.approx(msg.q.tolist()) and doc["by_name"]["joint_4"]["position"] == pytest.approx(
            msg.q[3]
        )
    for scan, msg in zip(seen[f"{k}/robot/base1/scan"], src[f"rf/{W}/robot/base1/scan"], strict=True):
        assert scan.frame_id == "base1/laser" and list(scan.ranges) == pytest.approx(msg.ranges.tolist())
        assert scan.start_angle == pytest.approx(-math.pi) and scan.end_angle == pytest.approx(
            -math.pi + 239 * 2 * math.pi / 240
        )
    (grid,) = seen[f"{k}/map/map"]
    g = _grid()
    assert grid.column_count == 20 and grid.row_stride == 20 and grid.cell_size.x == pytest.approx(0.05)
    assert np.array_equal(np.frombuffer(grid.data, dtype=np.uint8).reshape(12, 20), g.cells)
    assert (grid.pose.position.x, grid.pose.position.y) == (-1.0, -0.5)
    (path,) = seen[f"{k}/robot/base1/path"]
    assert [p.position.y for p in path.poses] == pytest.approx(np.sin(np.linspace(0.0, 2.0, 9)).tolist())
    tfs = [t for m in seen["/tf"] for t in m.transforms]
    children = Counter(t.child_frame_id for t in tfs)
    assert children["base1/base_link"] == N and children["arm1/base_link"] == N and children["arm1/link_6"] == N
    assert children["object/target"] == 3
    last_base = [t for t in tfs if t.child_frame_id == "base1/base_link"][-1]
    assert (last_base.translation.x, last_base.translation.y) == pytest.approx((0.05 * (N - 1), -0.02 * (N - 1)))
    arm_base = [t for t in tfs if t.child_frame_id == "arm1/base_link"][0]
    assert (arm_base.translation.x, arm_base.translation.z) == pytest.approx((3.0, 0.75))
    drawn = {e.frame_id for u in seen["/scene"] for e in u.entities}
    assert {"base1/base_link", "object/target", "map"} <= drawn and any(f.startswith("arm1/link_") for f in drawn), (
        drawn
    )


def _strict_json(data: bytes) -> object:
    """JSON as the standard has it: Python's json also reads NaN and Infinity, which no other reader does."""

    def refuse(word: str) -> None:
        raise ValueError(f"{word} is not JSON")

    return json.loads(data, parse_constant=refuse)


def test_foxglove_json_is_valid_json_a_non_finite_message_is_skipped_and_counted(tmp_path):
    """A message holding NaN or infinity (one the codec would refuse, built in-process) is not written:
    JSON has neither; every message written parses as standard JSON against its schema."""
    from user_peer.openfmt.foxglove import FoxgloveWriter

    names = ("joint_1", "joint_2")
    h = Header(0.0, T0, 0, "sim-1")
    fine = JointState(names, np.array([0.1, 0.2]), np.zeros(2), h)
    nan = JointState(names, np.array([0.1, 0.2]), np.array([np.nan, 0.0]), h)
    inf = Event("granted", reason="free", object="arm1", user="alice", data={"speed": math.inf}, header=h)
    out = tmp_path / "fox.mcap"
    with FoxgloveWriter(out) as w:
        for i, msg in enumerate((fine, nan, fine, inf)):
            w.write(f"rf/{W}/event/x" if msg is inf else f"rf/{W}/robot/arm9/joints", msg, T0 + i)
    assert (w.written, w.skipped) == (2, 2)
    docs = []
    with open(out, "rb") as f:
        for schema, _channel, message in make_reader(f).iter_messages():
            doc = _strict_json(message.data)
            jsonschema.validate(doc, json.loads(schema.data), cls=jsonschema.Draft202012Validator)
            docs.append(doc)
    assert [d["dq"] for d in docs] == [[0.0, 0.0], [0.0, 0.0]]


# --------------------------------------------------------------------------- ROS 2


def test_ros2_export_every_message_decodes_with_the_ros_types_and_values(recording, tmp_path):
    out = tmp_path / "ros2.mcap"
    stats = export_recording(recording, out, "ros2", scene="combined")
    assert (stats.messages, stats.bad, stats.skipped) == (len(source_messages()), 0, 0), stats
    src = _by_topic()
    seen: dict[str, list] = defaultdict(list)
    types: dict[str, str] = {}
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        n = 0
        for schema, channel, _message, decoded in reader.iter_decoded_messages():
            n += 1
            assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
            types[channel.topic] = schema.name
            seen[channel.topic].append(decoded)
    assert n == stats.written
    k = f"/rf/{W}"
    # the live bridge's topic names (user_peer.ros2): one rviz2 configuration for both
    assert types["/arm1/joint_states"] == "sensor_msgs/msg/JointState"
    assert types["/base1/scan"] == "sensor_msgs/msg/LaserScan"
    assert types["/base1/odom"] == "nav_msgs/msg/Odometry"
    assert types["/map"] == "nav_msgs/msg/OccupancyGrid"
    assert types["/base1/path"] == "nav_msgs/msg/Path"
    assert types["/object/target/pose"] == "geometry_msgs/msg/PoseStamped"
    assert types["/tf"] == "tf2_msgs/msg/TFMessage"
    assert types[f"{k}/own/arm1"] == "std_msgs/msg/String"  # no ROS place: named after its key

    for js, msg in zip(seen["/arm1/joint_states"], src[f"rf/{W}/robot/arm1/joints"], strict=True):
        assert list(js.name) == list(msg.names) and list(js.position) == pytest.approx(msg.q.tolist())
        assert list(js.velocity) == pytest.approx(msg.dq.tolist())
        # stamped with the sim's time (what /clock carries for use_sim_time), as the live bridge stamps
        assert js.header.stamp.sec * 10**9 + js.header.stamp.nanosec == round(msg.header.stamp * 1e9)
    for scan, msg in zip(seen["/base1/scan"], src[f"rf/{W}/robot/base1/scan"], strict=True):
        assert scan.header.frame_id == "base1/laser" and scan.range_max == pytest.approx(8.0)
        missing = msg.ranges >= 8.0 - 5e-4  # REP 117: no echo is +inf, never range_max
        assert missing.any() and (~missing).any()
        assert list(scan.ranges) == pytest.approx(np.where(missing, np.inf, msg.ranges).tolist(), abs=1e-6)
        assert scan.range_min == 0.0  # no world description in this recording: no sensor to ask
        assert scan.angle_increment == pytest.approx(2 * math.pi / 240)
    for od, msg in zip(seen["/base1/odom"], src[f"rf/{W}/robot/base1/pose"], strict=True):
        assert (od.header.frame_id, od.child_frame_id) == ("base1/odom", "base1/base_link")
        assert (od.pose.pose.position.x, od.pose.pose.position.y) == pytest.approx((msg.position[0], msg.position[1]))
        assert (od.pose.pose.orientation.w, od.pose.pose.orientation.z) == pytest.approx(
            (msg.quaternion[0], msg.quaternion[3])
        )
    (grid,) = seen["/map"]
    g = _grid()
    assert (grid.info.width, grid.info.height) == (20, 12) and grid.info.resolution == pytest.approx(0.05)
    cells = np.array(list(grid.data), dtype=np.int16).reshape(12, 20)
    assert np.array_equal(cells, np.where(g.cells == 255, -1, g.cells.astype(np.int16)))
    (path,) = seen["/base1/path"]
    assert [p.pose.position.x for p in path.poses] == pytest.approx(np.linspace(0.0, 2.0, 9).tolist())
    tfs = [t for m in seen["/tf"] for t in m.transforms]
    assert {"base1/odom", "base1/base_link", "arm1/base_link", "arm1/link_1", "base1/laser", "object/target"} <= {
        t.child_frame_id for t in tfs
    }
    own = [json.loads(s.data) for s in seen[f"{k}/own/arm1"]]
    assert [o["epoch"] for o in own] == [m.epoch for m in src[f"rf/{W}/own/arm1"]] and own[0]["queue"] == ["bob"]


# --------------------------------------------------------------------------- CLI


@pytest.mark.slow
def test_export_command_writes_each_format_and_refuses_mistakes(recording, tmp_path):
    for to in ("foxglove", "ros2"):
        out = subprocess.run(
            robofabric_cmd(
                "export", str(recording), "-o", str(tmp_path / f"{to}.mcap"), "--to", to, "--scene", "combined"
            ),
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert out.returncode == 0, out.stdout + out.stderr
        assert f"to {tmp_path / f'{to}.mcap'}" in out.stdout and (tmp_path / f"{to}.mcap").stat().st_size > 1000
    bad = subprocess.run(
        robofabric_cmd("export", str(recording), "-o", str(tmp_path / "x.mcap")),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2 and "--to" in bad.stderr, bad.stderr
    wrong = subprocess.run(
        robofabric_cmd("export", str(recording), "-o", str(tmp_path / "x.mcap"), "--to", "ros1"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert wrong.returncode == 2 and "foxglove" in wrong.stderr, wrong.stderr
