"""What a tool shows or records is all that happened: a native recording, a live ``--to ros2``
recording and ``echo`` on a wildcard of the same running sim hold the same messages, stream by stream.

Samples arrive out of timestamp order across the sim's publishers, so none of the three may order them by
timestamp (zenoh's advanced subscriber does, and drops the rest: once 2,397 of 3,000 poses in a minute's
ROS 2 file, with a progress line saying "0 dropped"). The native recorder (a plain subscriber)
is the reference: what reached this host. Messages are matched by their header's wall time, which the
ROS 2 writer keeps as each message's publish time; the first and last second are left out (the three
processes start and stop a few milliseconds apart).
"""

from __future__ import annotations

import json
from collections import defaultdict

import pytest
from mcap.reader import make_reader

from fabric.codec import decode
from user_peer.recordings import iter_messages
from robofabric.testing import robofabric_cmd, wait_until
from user_peer.openfmt.ros2 import ros2_topic

pytestmark = pytest.mark.slow  # a sim and three tools for 30 s

SECONDS = 30
STREAMS = ("robot/base1/pose", "robot/arm1/joints", "robot/base1/scan")
KINDS = {"base1": "mobile", "arm1": "arm"}  # a base's pose is its odometry in ROS 2


def _native(path) -> dict[str, list[int]]:
    out: dict[str, list[int]] = defaultdict(list)
    for m in iter_messages(path):
        header = getattr(decode(m.payload), "header", None)
        if header is not None:
            out[m.key].append(int(header.wall_ns))
    return out


def _ros2(path) -> dict[str, list[int]]:
    out: dict[str, list[int]] = defaultdict(list)
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            out[channel.topic].append(int(message.publish_time))
    return out


def _echo(text: str) -> dict[str, list[int]]:
    out: dict[str, list[int]] = defaultdict(list)
    for line in text.splitlines():
        if line.startswith("{"):
            doc = json.loads(line)
            out[doc["key"]].append(int(doc["message"]["header"]["wall_ns"]))
    return out


def _window(*series: list[int]) -> tuple[int, int]:
    """The time all of ``series`` cover, less its first and last second."""
    return max(min(s) for s in series) + 1_000_000_000, min(max(s) for s in series) - 1_000_000_000


def _inside(stamps: list[int], window: tuple[int, int]) -> list[int]:
    return sorted(t for t in stamps if window[0] <= t <= window[1])


def test_native_ros2_and_echo_hold_the_same_messages_per_stream(router, procs, world, tmp_path):
    fab, port = router
    ep = f"tcp/127.0.0.1:{port}"
    common = ("--world", world, "--connect", ep)
    sim = procs.start(robofabric_cmd("sim", "--scene", "combined", *common), name="sim")
    wait_until(lambda: fab.live_peers("sim"), timeout=60, what="sim peer", seen=lambda: procs.output(sim)[-2000:])
    native, ros2 = tmp_path / "native.mcap", tmp_path / "ros2.mcap"
    rec = procs.start(robofabric_cmd("record", "-o", str(native), "--duration", str(SECONDS), *common), name="record")
    live = procs.start(
        robofabric_cmd("record", "-o", str(ros2), "--to", "ros2", "--duration", str(SECONDS), *common),
        name="record-ros2",
    )
    echo = procs.start(
        robofabric_cmd("echo", "robot/*/pose", "--json", "--duration", str(SECONDS), *common), name="echo"
    )
    for proc in (rec, live, echo):
        assert proc.wait(timeout=SECONDS + 90) == 0, procs.output(proc)[-3000:]
    assert "0 dropped" in procs.output(live), procs.output(live)[-2000:]  # and it means it: checked below

    got_native, got_ros2, got_echo = _native(native), _ros2(ros2), _echo(procs.output(echo))
    for stream in STREAMS:
        key = f"rf/{world}/{stream}"
        a, b = got_native.get(key, []), got_ros2.get(ros2_topic(key, KINDS.get(stream.split("/")[1])), [])
        assert len(a) > 10 * (SECONDS - 5) and b, (stream, len(a), len(b))
        w = _window(a, b)
        assert _inside(b, w) == _inside(a, w), (
            f"{stream}: native {len(_inside(a, w))}, ros2 {len(_inside(b, w))} in the same window"
        )
    poses = [k for k in got_native if k.endswith("/pose") and "/robot/" in k]
    assert poses and set(poses) <= set(got_echo), (poses, sorted(got_echo))
    for key in poses:
        a, e = got_native[key], got_echo[key]
        w = _window(a, e)
        assert _inside(e, w) == _inside(a, w), (
            f"{key}: native {len(_inside(a, w))}, echo {len(_inside(e, w))} in the same window"
        )
