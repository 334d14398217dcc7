"""The recorder is bounded: a queue cap, a key cap and a disk quota; what is dropped is counted."""

from __future__ import annotations

import threading

import zenoh

from fabric import keys
from fabric.recording import Recorder
from user_peer.recordings import read_info
from robofabric.testing import wait_until


def _flood(pub, key_of, n, size):
    """Every sample reaches the recorder (BLOCK: zenoh drops none), so the recorder's own counts add up."""
    payload = b"\x00" * size
    for i in range(n):
        pub.session.put(key_of(i), payload, congestion_control=zenoh.CongestionControl.BLOCK)


def test_quota_and_key_cap_drop_and_count(tmp_path, world, connect):
    rec_fab, pub = connect("recorder", "rec"), connect("tool", "flooder")
    path = tmp_path / "r.mcap"
    rec = Recorder(rec_fab, path, quota_bytes=200_000, max_keys=10).start()
    try:
        wait_until(
            lambda: (pub.session.put(keys.robot_joints(world, "warm"), b"x"), rec.stats.messages)[1],
            timeout=30,
            what="the recorder hears the publisher",
        )
        _flood(pub, lambda i: keys.robot_joints(world, f"r{i}"), 50, 10)  # 50 keys: at most 10 recorded
        _flood(pub, lambda i: keys.robot_joints(world, "warm"), 100, 10_000)  # 1 MB on one key: the quota stops it
        # at least 40 keys over the cap and 70 samples over the quota; which ones depends on how many warm-up
        # samples arrived (they count as bytes and as a key), so wait until both counts are reached, not the first
        wait_until(
            lambda: rec.stats.dropped >= 40 + 70 and rec.stats.dropped_bytes >= 700_000,
            timeout=30,
            what="drops counted",
            seen=lambda: rec.stats,
        )
    finally:
        stats = rec.close()
    assert stats.quota_reached and stats.keys <= 10
    assert stats.payload_bytes <= 200_000 and stats.dropped_bytes >= 700_000
    assert "DROPPED" in stats.line() and "quota" in stats.line()
    assert read_info(path).messages == stats.messages


def test_queue_cap_drops_instead_of_growing(tmp_path, world, connect):
    rec_fab, pub = connect("recorder", "rec"), connect("tool", "flooder")
    rec = Recorder(rec_fab, tmp_path / "q.mcap", max_queue_bytes=1_000_000).start()
    try:
        wait_until(
            lambda: (pub.session.put(keys.robot_joints(world, "a"), b"x"), rec.stats.messages)[1],
            timeout=30,
            what="the recorder hears the publisher",
        )
        held = threading.Event()
        write = rec.sink.write

        def slow_write(*args):  # a disk that does not keep up: the queue only fills
            held.wait(60)
            return write(*args)

        rec.sink.write = slow_write
        try:
            _flood(pub, lambda i: keys.robot_joints(world, "a"), 40, 100_000)
            wait_until(
                lambda: rec.stats.dropped >= 25, timeout=30, what="drops while the disk is held", seen=lambda: rec.stats
            )
            assert rec.stats.queued_bytes <= 1_000_000
        finally:
            held.set()
        wait_until(
            lambda: rec.stats.messages + rec.stats.dropped >= 41,
            timeout=30,
            what="every sample written or dropped",
            seen=lambda: rec.stats,
        )
    finally:
        stats = rec.close()
    assert stats.dropped >= 25 and stats.messages + stats.dropped >= 41
