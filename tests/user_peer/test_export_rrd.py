"""`robofabric export FILE.mcap -o FILE.rrd`: the viewer's entities, from a recording read with the mcap package."""

import math
import subprocess

import numpy as np
from mcap.writer import Writer
import pytest

from fabric import keys
from fabric.codec import encode
from fabric.interfaces import Header, JointState, OccupancyGrid, Path, Pose, Scan
from robofabric.testing import robofabric_cmd
from user_peer.export import export_mcap
from userpeer_rrd import entities_with_data, rows_per_entity

ARM_JOINTS = ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6")


def write_recording(path, world="demo", n=40, truncate=False):
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=4096)
        w.start(profile="robofabric", library="test")
        channels = {}
        schemas = {}

        def put(key, msg, t):
            name = type(msg).__name__
            if name not in schemas:
                schemas[name] = w.register_schema(name=name, encoding="robofabric-msgpack", data=b"")
            if key not in channels:
                channels[key] = w.register_channel(topic=key, message_encoding="msgpack", schema_id=schemas[name])
            w.add_message(channels[key], log_time=t, publish_time=t, data=encode(msg))

        t0 = 1_700_000_000_000_000_000
        for i in range(n):
            t = t0 + i * 50_000_000
            h = Header(stamp=i * 0.05, wall_ns=t, seq=i, source="sim")
            put(keys.robot_joints(world, "arm1"), JointState(ARM_JOINTS, np.full(6, 0.02 * i), np.full(6, 0.4), h), t)
            yaw = 0.05 * i
            put(
                keys.robot_pose(world, "base1"),
                Pose([0.05 * i, 0, 0], [math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)], header=h),
                t,
            )
            put(
                keys.robot_scan(world, "base1"),
                Scan.from_ranges(
                    np.full(240, 2.5), angle_min=-1.178, angle_increment=2.356 / 239, range_max=12.0, header=h
                ),
                t,
            )
        put(keys.map_key(world, "base1"), OccupancyGrid(0.05, [-5, -5, 0], np.zeros((100, 100), np.uint8)), t0)
        put(keys.robot_path(world, "base1"), Path([0, 1, 2], [0, 1, 1], [0, 0.5, 0]), t0)
        w.add_message(channels[keys.robot_pose(world, "base1")], log_time=t0, publish_time=t0, data=b"garbage")
        if truncate:
            f.flush()
            return
        w.finish()


def test_export_draws_robots_scans_maps_and_paths(tmp_path):
    src, dst = tmp_path / "rec.mcap", tmp_path / "rec.rrd"
    write_recording(src)
    stats = export_mcap(src, dst, scene="combined")
    assert stats.messages == 122 and stats.bad == 1
    assert stats.robots == ("arm1", "base1")
    rows = rows_per_entity(dst)
    links = entities_with_data(dst, "/world/robots/arm1/links/")
    joints = [e for e in links if e.rsplit("/", 1)[-1].startswith("joint_")]
    assert len(joints) == 6 and all(rows[e] == 40 for e in joints)  # one transform per joint and message
    shapes = [e for e in links if e.endswith("/shape")]
    assert len(shapes) == 7 and all(rows[e] == 1 for e in shapes)  # meca500's seven visual shapes, logged once
    assert "/world/robots/arm1/links/joint_1/joint_2/link_2_0/shape" in shapes  # each below its joint
    assert rows["/world/robots/arm1/skeleton"] == 41  # 40 rows, and its style once
    assert rows["/plots/joints/arm1"] == 41  # six series in one entity (and their names once)
    assert rows["/world/robots/base1/scan"] == 41  # 40 scans (hits and rays), and their style once
    assert rows["/world/robots/base1/base"] == 40
    assert rows["/map/base1"] == 1
    assert rows["/world/robots/base1/path"] == 1
    assert rows["/world/scene"] == 1  # the combined scene's walls, shelves and table, drawn once


@pytest.mark.slow
def test_export_cli_and_bad_files(tmp_path):
    src, dst = tmp_path / "rec.mcap", tmp_path / "out.rrd"
    write_recording(src, n=5)
    ok = subprocess.run(
        robofabric_cmd("export", str(src), "-o", str(dst), "--scene", "combined"),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert ok.returncode == 0, ok.stderr
    assert "exported 17 messages" in ok.stdout and "arm1" in ok.stdout
    assert rows_per_entity(dst)["/world/robots/base1/scan"] == 6  # 5 scans and their style
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    for bad in (junk, tmp_path / "missing.mcap"):
        r = subprocess.run(
            robofabric_cmd("export", str(bad), "-o", str(dst)), capture_output=True, text=True, timeout=120
        )
        assert r.returncode == 2 and r.stderr.count("\n") <= 6, r.stderr
        assert "error:" in r.stderr


def test_export_reads_a_truncated_recording(tmp_path):
    src, dst = tmp_path / "cut.mcap", tmp_path / "cut.rrd"
    write_recording(src, n=40, truncate=True)
    data = src.read_bytes()
    src.write_bytes(data[: len(data) - 100])
    stats = export_mcap(src, dst, scene="combined")
    assert 0 < stats.messages < 122
    assert rows_per_entity(dst)["/world/robots/base1/scan"] > 0


def test_export_of_a_live_recording(world, connect, tmp_path):
    from fabric.recording import Recorder
    from robofabric.testing import wait_until

    pub = connect("sim", "fake-sim")
    rec_fab = connect("recorder", "rec")
    src, dst = tmp_path / "live.mcap", tmp_path / "live.rrd"
    with Recorder(rec_fab, src) as rec:
        i = 0

        def step():
            nonlocal i
            h = Header(stamp=i * 0.05, wall_ns=0, seq=i)
            pub.publish(keys.robot_pose(world, "base1"), Pose([0.1 * i, 0, 0], header=h))
            pub.publish(
                keys.robot_scan(world, "base1"),
                Scan.from_ranges(
                    np.full(240, 3.0), angle_min=-1.178, angle_increment=0.00986, range_max=12.0, header=h
                ),
            )
            i += 1
            return rec.stats.messages >= 20

        wait_until(step, timeout=15, interval=0.05, what="20 recorded messages")
    stats = export_mcap(src, dst)
    assert stats.messages >= 20 and stats.bad == 0 and stats.robots == ("base1",)
    rows = rows_per_entity(dst)
    assert rows["/world/robots/base1/scan"] >= 10 and rows["/world/robots/base1/base"] >= 10
