"""``robofabric record --to foxglove|ros2``: a live world written straight into another format."""

from __future__ import annotations

import json
import signal

import jsonschema
import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from fabric import keys
from fabric.interfaces import Header, JointState, OccupancyGrid, Scan
from robofabric.testing import robofabric_cmd, wait_until

pytestmark = pytest.mark.slow


def _record(procs, tmp_path, world, port, to):
    out = tmp_path / f"live-{to}.mcap"
    proc = procs.start(
        robofabric_cmd(
            "record", "-o", str(out), "--to", to, "-q", "--world", world, "--connect", f"tcp/127.0.0.1:{port}"
        ),
        name=f"record-{to}",
    )
    return out, proc


def _publish_world(fab, world, n=40):
    names = ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6")
    cells = np.zeros((8, 10), dtype=np.uint8)
    cells[2, 3] = 100
    cells[5:, :] = 255
    fab.publish(keys.map_key(world, "map"), OccupancyGrid(0.1, np.zeros(3), cells))
    for i in range(n):
        h = Header.now(stamp=i * 0.05, seq=i, source="test")
        fab.publish(keys.robot_joints(world, "arm1"), JointState(names, np.full(6, 0.01 * i), np.zeros(6), h))
        fab.publish(
            keys.robot_scan(world, "base1"),
            Scan.from_ranges(np.full(60, 1.5), angle_min=-1.0, angle_increment=0.03, range_max=5.0, header=h),
        )
    fab.session.put(keys.event(world, "raw"), b"\x00not a fabric message")


# Both formats live: each writer is checked message by message against a source in
# tests/user_peer/test_openfmt.py; here the live path (record --to, LiveConverter, the entry points) is:
# ros2's decoder checks the CDR, Foxglove's JSON is validated against its schema and its protobuf parsed.
@pytest.mark.parametrize("to", ["ros2", "foxglove"])
def test_record_to_writes_a_live_world_in_the_format(router, connect, world, procs, tmp_path, to):
    _fab, port = router
    out, proc = _record(procs, tmp_path, world, port, to)
    pub = connect("tool")
    wait_until(
        lambda: pub.live_peers("recorder", timeout=0.5),
        timeout=60,
        what="the recorder to join",
        seen=lambda: procs.output(proc),
    )
    sent = []

    def publish_until_seen():
        _publish_world(pub, world)
        sent.append(1)
        return out.exists() and out.stat().st_size > 0 and len(sent) >= 2

    wait_until(publish_until_seen, timeout=30, interval=0.2, what="two rounds published")
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=60) == 0, procs.output(proc)
    text = procs.output(proc)
    assert f"-> {out} ({to})" in text and "undecodable" in text, text

    topics = {}
    n = 0
    with open(out, "rb") as f:
        if to == "ros2":
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for schema, channel, _m, decoded in reader.iter_decoded_messages():
                n += 1
                topics[channel.topic] = schema.name
                if schema.name == "sensor_msgs/msg/JointState":
                    assert list(decoded.name)[0] == "joint_1" and len(decoded.position) == 6
                if schema.name == "nav_msgs/msg/OccupancyGrid":
                    assert (decoded.info.width, decoded.info.height) == (10, 8) and list(decoded.data).count(-1) == 30
        else:
            for schema, channel, message in make_reader(f).iter_messages():
                n += 1
                topics[channel.topic] = schema.name
                if channel.message_encoding == "json":
                    doc = json.loads(message.data)
                    jsonschema.validate(doc, json.loads(schema.data), cls=jsonschema.Draft202012Validator)
                    if schema.name == "robofabric.JointState":
                        assert doc["names"][0] == "joint_1" and len(doc["q"]) == 6 and "joint_6" in doc["by_name"]
                else:
                    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
                    pool = descriptor_pool.DescriptorPool()
                    for fd in fds.file:
                        pool.Add(fd)
                    m = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))()
                    m.ParseFromString(message.data)
                    if schema.name == "foxglove.Grid":
                        cells = np.frombuffer(m.data, dtype=np.uint8).reshape(8, 10)
                        assert m.column_count == 10 and cells[2, 3] == 100 and (cells[5:] == 255).all()
                    if schema.name == "foxglove.LaserScan":
                        assert len(m.ranges) == 60 and m.ranges[0] == pytest.approx(1.5)
    assert n >= 80, (n, topics)
    k = f"/rf/{world}"
    expect = (
        {
            "/arm1/joint_states": "sensor_msgs/msg/JointState",
            "/base1/scan": "sensor_msgs/msg/LaserScan",
            "/map": "nav_msgs/msg/OccupancyGrid",
        }
        if to == "ros2"  # the live bridge's names (docs/ros2.md)
        else {
            f"{k}/robot/arm1/joints": "robofabric.JointState",
            f"{k}/robot/base1/scan": "foxglove.LaserScan",
            f"{k}/map/map": "foxglove.Grid",
        }
    )
    for topic, name in expect.items():
        assert topics.get(topic) == name, topics
