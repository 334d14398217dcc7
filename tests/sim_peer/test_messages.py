"""WorldInfo survives the codec exactly, and malformed ones are refused with a clear error."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabric.codec import DecodeError, decode, encode, messages_equal
from fabric.interfaces import ObjectInfo, RobotInfo, WorldInfo

ids = st.text("abcdefghijklmnopqrstuvwxyz0123456789_-", min_size=1, max_size=12)
fl = st.floats(-1e3, 1e3, allow_nan=False)


@st.composite
def robot_infos(draw):
    n = draw(st.integers(0, 7))
    arr = lambda k: np.array(draw(st.lists(fl, min_size=k, max_size=k)))  # noqa: E731
    return RobotInfo(
        id=draw(ids), type=draw(ids), kind=draw(st.sampled_from(["arm", "mobile"])), pose=arr(4),
        joint_names=tuple(draw(st.lists(ids, min_size=n, max_size=n))), lower=arr(n), upper=arr(n), max_speed=arr(n),
        base_radius=draw(st.floats(0, 5)), base={"max_speed": draw(fl)}, sensors={"lidar_rays": draw(st.integers(1, 4096)), "lidar_offset": [0.1, 0.0, 0.2]},
    )


@settings(max_examples=60, deadline=None)
@given(st.lists(robot_infos(), max_size=4, unique_by=lambda r: r.id), st.lists(ids, max_size=3), st.floats(1e-4, 0.1))
def test_world_info_round_trips(robots, objs, dt):
    objects = tuple(ObjectInfo(o, "ik_target", "scene", np.zeros(3), np.array([1.0, 0, 0, 0])) for o in objs)
    info = WorldInfo("w", "combined", dt, {"joints": 100.0}, tuple(robots), objects)
    back = decode(encode(info), WorldInfo)
    assert messages_equal(back, info)


def test_malformed_world_info_is_refused():
    good = RobotInfo("a", "meca500", "arm", np.zeros(4), ("j1",), np.zeros(1), np.ones(1), np.ones(1))
    raw = msgpack.unpackb(encode(WorldInfo("w", "s", 0.002, {}, (good,))), raw=False, strict_map_key=False)
    raw[5] = "not a list"
    with pytest.raises(DecodeError, match="WorldInfo.robots: expected a list of messages"):
        decode(msgpack.packb(raw, use_bin_type=True))
    with pytest.raises(ValueError, match="1 joints but limits"):
        encode(WorldInfo("w", "s", 0.002, {}, (RobotInfo("a", "m", "arm", np.zeros(4), ("j1",), np.zeros(2), np.ones(1), np.ones(1)),)))
