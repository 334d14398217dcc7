"""What a tool shows or records is all that happened: a native recording, a live ``--to ros2``
recording and ``echo`` on a wildcard of the same running sim hold the same messages, stream by stream.

Samples arrive out of timestamp order across the sim's publishers, so none of the three may order them by
timestamp (zenoh's advanced subscriber does, and drops the rest: once 2,397 of 3,000 poses in a minute's
ROS 2 file, with a progress line saying "0 dropped"). The native recorder (a plain subscriber)
is the reference: what reached this host. Messages are matched by their header's wall time, which the
ROS 2 writer keeps as each message's publish time; the first and last second are left out (the three
processes start and stop a few milliseconds apart).

At load a tool's process can stand still for seconds (a whole run's load 15: the ROS 2 recorder missed 3.7 s of
base1's poses, 184 in a row, while the native one had them). Its link's queue at the router fills and zenoh drops
best-effort samples on the way, a stretch of every stream at once: no tool can hold what never reached it. So a
message one tool lacks is allowed only inside a stretch of STALL_S or more in which that tool holds nothing of the
stream, and only as many as the recorder itself says never reached it (``MISSED N msgs on the way``: the
publishers number their samples, fabric/recording/gaps.py); every such stretch is printed. A tool that drops what
reached it (an advanced subscriber ordering by timestamp drops samples between the ones it keeps, a few at a
time) leaves short gaps, and fails.
"""

from __future__ import annotations

import bisect
import json
import re
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
STALL_S = 1.0  # a stretch this long with nothing of a stream: the tool's process stood still, not the tool


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


def _stalls(held: list[int], lacks: set[int]) -> tuple[list[int], list[str]]:
    """Of ``lacks`` (messages a tool does not hold), those that fall between two of its own ``held`` messages
    less than STALL_S apart (the tool's fault), and the stretches of STALL_S or more that excuse the rest."""
    short: list[int] = []
    stretches: set[tuple[int | None, int | None]] = set()
    for t in sorted(lacks):
        i = bisect.bisect_left(held, t)
        before, after = held[i - 1] if i else None, held[i] if i < len(held) else None
        if before is None or after is None or after - before >= STALL_S * 1e9:
            stretches.add((before, after))
        else:
            short.append(t)
    said = [
        f"{(b - a) / 1e9 if a is not None and b is not None else float('inf'):.1f} s with nothing (missing "
        f"{sum(1 for t in lacks if (a is None or a < t) and (b is None or t < b))})"
        for a, b in sorted(stretches, key=lambda ab: ab[0] or 0)
    ]
    return short, said


def _missed(output: str) -> int:
    """What a recorder's last line says never reached it (0 when it says nothing)."""
    found = re.findall(r"^recorded .*MISSED (\d+) msgs on the way", output, re.M)
    return int(found[-1]) if found else 0


def _same(name: str, ref: list[int], other: list[int], what: str) -> tuple[int, int]:
    """``other`` holds what ``ref`` holds in the window both cover, except where one of them stood still;
    returns how many each lacks (``ref``'s, ``other``'s)."""
    w = _window(ref, other)
    a, b = _inside(ref, w), _inside(other, w)
    lacks_b, lacks_a = set(a) - set(b), set(b) - set(a)
    short_b, stalls_b = _stalls(b, lacks_b)
    short_a, stalls_a = _stalls(a, lacks_a)
    if stalls_a or stalls_b:
        print(f"{name}: native stood still {stalls_a or 'never'}, {what} {stalls_b or 'never'}")
    assert not short_a and not short_b, (
        f"{name}: native {len(a)}, {what} {len(b)} in the same window; {what} lacks {len(short_b)} and native "
        f"{len(short_a)} between messages they hold (first: {short_b[:3]}, {short_a[:3]}); stretches: "
        f"{stalls_b}, {stalls_a}"
    )
    # a stall is the box's, but a recording missing over a quarter of the window is too little to compare
    assert len(lacks_a) + len(lacks_b) <= 0.25 * len(a), (
        f"{name}: native {len(a)}, {what} {len(b)}: stretches {stalls_b}, {stalls_a} lose over a quarter"
    )
    return len(lacks_a), len(lacks_b)


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
    lacked = {"native": 0, "ros2": 0}
    for stream in STREAMS:
        key = f"rf/{world}/{stream}"
        a, b = got_native.get(key, []), got_ros2.get(ros2_topic(key, KINDS.get(stream.split("/")[1])), [])
        assert len(a) > 10 * (SECONDS - 5) and b, (stream, len(a), len(b))
        lacks = _same(stream, sorted(a), sorted(b), "ros2")
        lacked["native"] += lacks[0]
        lacked["ros2"] += lacks[1]
    # a stretch a recorder lacks is one it says never reached it, not one it lost itself
    said = {"native": _missed(procs.output(rec)), "ros2": _missed(procs.output(live))}
    assert all(lacked[k] <= said[k] for k in said), f"lacked {lacked}, the recorders said they missed {said}"
    poses = [k for k in got_native if k.endswith("/pose") and "/robot/" in k]
    assert poses and set(poses) <= set(got_echo), (poses, sorted(got_echo))
    for key in poses:
        _same(key, sorted(got_native[key]), sorted(got_echo[key]), "echo")
