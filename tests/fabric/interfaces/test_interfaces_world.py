"""WorldInfo survives the codec exactly, typed sensors included, and malformed ones are refused with a clear error."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabric.codec import DecodeError, decode, encode, messages_equal
from fabric.interfaces import BaseInfo, LidarInfo, ObjectInfo, RobotInfo, SonarInfo, WorldInfo
from user_peer.message_schema import json_schema, plain_view

ids = st.text("abcdefghijklmnopqrstuvwxyz0123456789_-", min_size=1, max_size=12)
fl = st.floats(-1e3, 1e3, allow_nan=False)
pos = st.floats(0, 100, allow_nan=False)


@st.composite
def base_infos(draw):
    return BaseInfo(*(draw(pos) for _ in range(7)), height=draw(pos))


@st.composite
def lidar_infos(draw):
    lo = draw(st.floats(0, 1))
    return LidarInfo(
        site=draw(ids),
        rays=draw(st.integers(1, 4096)),
        fov=draw(st.floats(0, 6.28)),
        angle_min=draw(st.floats(-3.14, 0)),
        angle_increment=draw(st.floats(0, 0.1)),
        range_min=lo,
        range_max=lo + draw(pos),
        noise_std=draw(st.floats(0, 0.1)),
        offset=np.array(draw(st.lists(fl, min_size=3, max_size=3))),
    )


@st.composite
def sonar_infos(draw):
    lo = draw(st.floats(0, 1))
    return SonarInfo(
        angles=np.array(draw(st.lists(st.floats(-3.14, 3.14), max_size=12))),
        radius=draw(pos),
        height=draw(fl),
        range_min=lo,
        range_max=lo + draw(pos),
        center=np.array(draw(st.lists(fl, min_size=2, max_size=2))),
    )


@st.composite
def robot_infos(draw):
    n = draw(st.integers(0, 7))
    arr = lambda k: np.array(draw(st.lists(fl, min_size=k, max_size=k)))  # noqa: E731
    return RobotInfo(
        id=draw(ids),
        type=draw(ids),
        kind=draw(st.sampled_from(["arm", "mobile"])),
        pose=arr(4),
        joint_names=tuple(draw(st.lists(ids, min_size=n, max_size=n))),
        lower=arr(n),
        upper=arr(n),
        max_speed=arr(n),
        base_radius=draw(st.floats(0, 5)),
        base=draw(st.none() | base_infos()),
        lidar=draw(st.none() | lidar_infos()),
        sonar=draw(st.none() | sonar_infos()),
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
        encode(
            WorldInfo(
                "w",
                "s",
                0.002,
                {},
                (RobotInfo("a", "m", "arm", np.zeros(4), ("j1",), np.zeros(2), np.ones(1), np.ones(1)),),
            )
        )


def _mobile(**kw) -> RobotInfo:
    return RobotInfo("base1", "reeman", "mobile", np.zeros(4), (), np.zeros(0), np.zeros(0), np.zeros(0), **kw)


LIDAR = LidarInfo("lidar", 240, 2.356, -1.178, 0.00985, 0.05, 12.0, offset=np.array([0.22, 0.0, 0.3]))


def test_sensors_are_typed_fields_and_absent_ones_are_none():
    info = _mobile(base=BaseInfo(0.25, 0.4, 0.08, 1.0, 2.0, 1.0, 2.0), lidar=LIDAR)
    back = decode(encode(WorldInfo("w", "s", 0.002, {}, (info,))), WorldInfo).robot("base1")
    assert (
        back.lidar.rays == 240
        and back.lidar.offset.tolist() == [0.22, 0.0, 0.3]
        and not back.lidar.offset.flags.writeable
    )
    assert back.base.max_speed == 1.0 and back.sonar is None
    arm = RobotInfo("arm1", "meca500", "arm", np.zeros(4), ("j1",), np.zeros(1), np.ones(1), np.ones(1))
    assert decode(encode(WorldInfo("w", "s", 0.002, {}, (arm,))), WorldInfo).robots[0].lidar is None


def test_malformed_sensors_are_refused_naming_the_field():
    raw = msgpack.unpackb(
        encode(WorldInfo("w", "s", 0.002, {}, (_mobile(lidar=LIDAR),))), raw=False, strict_map_key=False
    )
    robot = raw[5][0]
    lidar_at = 1 + list(RobotInfo.SPEC).index("lidar")
    robot[lidar_at][2] = 0  # rays
    with pytest.raises(DecodeError, match=r"LidarInfo.rays: 0 is outside \[1, 8192\]"):
        decode(msgpack.packb(raw, use_bin_type=True))
    robot[lidar_at] = {"lidar_rays": 240}  # the old string-keyed form is not a LidarInfo
    with pytest.raises(DecodeError, match="RobotInfo.lidar: expected a nested message"):
        decode(msgpack.packb(raw, use_bin_type=True))
    robot[lidar_at] = msgpack.unpackb(encode(SonarInfo(np.zeros(3), 0.2, 0.1, 0.0, 1.0)), raw=False)
    with pytest.raises(DecodeError, match="RobotInfo.lidar: expected LidarInfo, got SonarInfo"):
        decode(msgpack.packb(raw, use_bin_type=True))
    with pytest.raises(ValueError, match="range_max 1.0 < range_min 2.0"):
        encode(WorldInfo("w", "s", 0.002, {}, (_mobile(sonar=SonarInfo(np.zeros(3), 0.2, 0.1, 2.0, 1.0)),)))


def test_optional_fields_are_in_the_json_schema():
    """A robot with or without its optional parts validates against WorldInfo's schema; a part of the wrong
    shape does not."""
    import jsonschema

    schema = json_schema(WorldInfo)
    for info in (_mobile(lidar=LIDAR, base=BaseInfo(0.25, 0.4, 0.08, 1.0, 2.0, 1.0, 2.0)), _mobile()):
        jsonschema.validate(plain_view(WorldInfo("w", "s", 0.002, {}, (info,))), schema)
    with pytest.raises(jsonschema.ValidationError):
        bad = plain_view(WorldInfo("w", "s", 0.002, {}, (_mobile(lidar=LIDAR),)))
        bad["robots"][0]["lidar"] = {"lidar_rays": 240}
        jsonschema.validate(bad, schema)
