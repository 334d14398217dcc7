"""A user's cache of the latest message per key holds what the world has, not what clients make up."""

from __future__ import annotations

from types import SimpleNamespace

from fabric import keys
from user_peer.latest import Latest

W = "w"
INFO = SimpleNamespace(
    robots=[SimpleNamespace(id="arm1"), SimpleNamespace(id="base1")], objects=[SimpleNamespace(id="target")]
)


def test_keys_of_robots_the_world_does_not_have_are_not_kept():
    info = [None]
    latest = Latest(world_info=lambda: info[0], max_other=8)
    info[0] = INFO
    latest.put(keys.robot_stream(W, "arm1", "joints"), "q")
    latest.put(keys.own(W, "arm1"), "record")
    latest.put(keys.object_pose_all(W, "target"), "pose")
    for i in range(1000):  # a flood of made-up robots, each a 4 MiB scan in the report
        latest.put(keys.robot_stream(W, f"fake{i}", "scan"), b"x")
        latest.put(keys.own(W, f"fake{i}"), "forged")
    assert latest.dropped == 2000 and latest.get(keys.robot_stream(W, "fake3", "scan")) is None
    assert len(latest) == 3
    for i in range(100):  # other keys (events, maps) share a few places; the world's keys keep theirs
        latest.put(keys.event(W, "decode", f"u{i}"), i)
    assert len(latest) == 3 + 8 and latest.get(keys.event(W, "decode", "u99")) == 99
    assert latest.get(keys.event(W, "decode", "u0")) is None  # the least recently updated went first
    assert latest.get(keys.robot_stream(W, "arm1", "joints")) == "q" and latest.get(keys.own(W, "arm1")) == "record"
    assert latest.get(keys.object_pose_all(W, "target")) == "pose"


def test_before_the_world_description_every_key_shares_the_bounded_places():
    info = [None]
    latest = Latest(world_info=lambda: info[0], max_other=16)
    for i in range(500):
        latest.put(keys.robot_stream(W, f"r{i}", "scan"), i)
    assert len(latest) == 16 and latest.get(keys.robot_stream(W, "r499", "scan")) == 499
    latest.put(keys.robot_stream(W, "r499", "scan"), "again")
    info[0] = SimpleNamespace(robots=[SimpleNamespace(id="r499")], objects=[])
    latest.put(keys.robot_stream(W, "r499", "scan"), "known now")  # a key of the world leaves the shared places
    for i in range(100):
        latest.put(keys.event(W, "decode", f"u{i}"), i)
    assert latest.get(keys.robot_stream(W, "r499", "scan")) == "known now" and len(latest) == 17
