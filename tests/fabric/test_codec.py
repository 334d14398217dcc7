"""Codec: exact round trips, and nothing but DecodeError out of hostile bytes."""

import dataclasses
import math

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fabric.codec import DecodeError, decode, encode, messages_equal, to_plain
from fabric.interfaces import (
    Command,
    Event,
    Header,
    JointState,
    JointTarget,
    JointTrajectory,
    OccupancyGrid,
    OwnershipRecord,
    Path,
    Pose,
    Reset,
    Scan,
    Stop,
    Twist,
)

finite = st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e9, max_value=1e9)
text = st.text(max_size=20)
headers = st.builds(Header, stamp=finite, wall_ns=st.integers(0, 2**63 - 1), seq=st.integers(0, 2**32), source=text)


def farr(shape):
    return hnp.arrays(np.float64, shape, elements=finite)


def joint_states():
    return st.integers(0, 12).flatmap(
        lambda n: st.builds(JointState, st.lists(text, min_size=n, max_size=n), farr(n), farr(n), headers)
    )


def unit_quats():
    return farr(4).filter(lambda q: np.linalg.norm(q) > 1e-3).map(lambda q: q / np.linalg.norm(q))


poses = st.builds(Pose, farr(3), unit_quats(), farr(3), farr(3), text, headers)
scans = st.builds(
    Scan,
    st.floats(-6.0, 6.0),
    st.floats(-3.0, 3.0),
    st.floats(0.0, 65.0),
    hnp.arrays(np.uint16, st.integers(0, 400)),
    headers,
)
paths = st.integers(0, 50).flatmap(lambda n: st.builds(Path, farr(n), farr(n), farr(n), text, headers))
cell_values = st.one_of(st.integers(0, 100), st.just(255))
grids = st.builds(
    OccupancyGrid,
    st.floats(0.001, 10.0),
    farr(3),
    hnp.arrays(np.uint8, hnp.array_shapes(min_dims=2, max_dims=2, max_side=20), elements=cell_values),
    headers,
)
trajectories = st.tuples(st.integers(1, 20), st.integers(1, 8)).flatmap(
    lambda nk: st.builds(
        JointTrajectory,
        hnp.arrays(np.float64, nk[0], elements=st.floats(0.0, 1e3)).map(np.sort),
        hnp.arrays(np.float64, nk, elements=st.floats(-10.0, 10.0)),
        headers,
    )
)
bodies = st.one_of(
    st.builds(JointTarget, farr(st.integers(0, 8)), st.floats(0.01, 1.0), headers),
    trajectories,
    st.builds(Twist, finite, finite, headers),
    paths,
    st.builds(Stop, headers),
    st.builds(Reset, headers),
)
users = st.from_regex(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}", fullmatch=True)  # fabric.limits.USER_PATTERN
commands = st.builds(Command, users, st.integers(0, 2**40), bodies, headers)
records = st.builds(
    OwnershipRecord,
    text.filter(bool),
    st.sampled_from(["scene", "exclusive"]),
    text,
    st.integers(0, 2**40),
    finite,
    st.lists(text, max_size=5),
    st.sampled_from(["still", "moving"]),
    text,
    headers,
)
scalars = st.one_of(st.none(), st.booleans(), st.integers(-(2**63), 2**63 - 1), finite, text)
events = st.builds(
    Event,
    text.filter(bool),
    text,
    text,
    text,
    st.sampled_from(["debug", "info", "warning", "error"]),
    st.dictionaries(text, st.one_of(scalars, st.lists(scalars, max_size=3)), max_size=4),
    headers,
)
messages = st.one_of(joint_states(), poses, scans, paths, grids, commands, records, events)


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)  # no timing: CI shares its cores
@given(messages)
def test_round_trip_is_exact(msg):
    back = decode(encode(msg))
    assert messages_equal(back, msg), (msg, back)
    assert encode(back) == encode(msg)


@settings(max_examples=500, deadline=None)
@given(st.binary(max_size=300))
def test_random_bytes_raise_only_decode_error(data):
    try:
        decode(data)
    except DecodeError:
        pass


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)  # no timing: CI shares its cores
@given(messages, st.data())
def test_truncated_or_corrupted_payloads_raise_only_decode_error(msg, data):
    payload = bytearray(encode(msg))
    cut = data.draw(st.integers(0, len(payload) - 1))
    with pytest.raises(DecodeError):
        decode(bytes(payload[:cut]))
    i = data.draw(st.integers(0, len(payload) - 1))
    payload[i] = data.draw(st.integers(0, 255))
    try:
        decode(bytes(payload))
    except DecodeError:
        pass


def test_scan_of_240_rays_fits_600_bytes():
    rng = np.random.default_rng(0)
    scan = Scan.from_ranges(
        rng.random(240) * 12,
        angle_min=-1.178,
        angle_increment=0.00985,
        range_max=12.0,
        header=Header.now(stamp=12345.678, seq=2**31, source="sim-host-abcdef"),
    )
    assert len(encode(scan)) <= 600


def test_scan_quantises_to_millimetres_and_maps_misses_to_range_max():
    s = Scan.from_ranges([1.2344, np.inf, np.nan, -1.0, 99.0], angle_min=0.0, angle_increment=0.1, range_max=10.0)
    assert s.ranges_mm.tolist() == [1234, 10000, 10000, 10000, 10000]
    assert s.ranges[0] == pytest.approx(1.234)


def _raw(name, *fields):
    return msgpack.packb([name, *fields], use_bin_type=True)


H = ["Header", 0.0, 0, 0, ""]


@pytest.mark.parametrize(
    "payload,needle",
    [
        (_raw("Twist", float("nan"), 0.0, H), "Twist.v: must be finite"),
        (_raw("Twist", 1.0, float("inf"), H), "Twist.omega: must be finite"),
        (_raw("Twist", "fast", 0.0, H), "Twist.v: expected a number"),
        (_raw("Twist", 1.0, H), "expected 3 fields"),
        (_raw("Teleport", 1.0), "unknown message type 'Teleport'"),
        (msgpack.packb({"a": 1}), "expected a message array"),
        (_raw("Stop", ["Header", 0.0, -5, 0, ""]), "Header.wall_ns"),
        (_raw("Command", "", 0, ["Stop", H], H), "Command.user: must not be empty"),
        (_raw("Command", "bob", 1, ["Event", "x", "", "", "", "info", {}, H], H), "expected JointTarget"),
        (_raw("OwnershipRecord", "arm", "shared", "", 0, 0.0, [], "still", "", H), "'shared' is not one of"),
    ],
)
def test_invalid_fields_are_named(payload, needle):
    with pytest.raises(DecodeError) as err:
        decode(payload)
    assert needle in str(err.value)


def test_nan_inside_array_and_wrong_shapes_are_refused():
    good = encode(Pose(np.zeros(3)))
    pose = decode(good)
    bad_pos = np.array([0.0, math.nan, 0.0])
    with pytest.raises(ValueError):
        encode(JointState(["a"], [1.0, 2.0], [0.0]))
    raw = msgpack.unpackb(good, raw=False, ext_hook=lambda c, d: msgpack.ExtType(c, d))
    # Replace the position ext with one holding a NaN, and then with a 2-vector.
    from fabric.codec.wire import array_ext

    raw[1] = array_ext(bad_pos)
    with pytest.raises(DecodeError, match="position: element 1 is not finite"):
        decode(msgpack.packb(raw, use_bin_type=True))
    raw[1] = array_ext(np.zeros(2))
    with pytest.raises(DecodeError, match=r"expected shape \(3,\)"):
        decode(msgpack.packb(raw, use_bin_type=True))
    raw[1] = array_ext(np.zeros(3, dtype=np.float32))
    with pytest.raises(DecodeError, match="expected dtype float64"):
        decode(msgpack.packb(raw, use_bin_type=True))
    assert messages_equal(pose, Pose(np.zeros(3)))


def test_a_trajectory_whose_times_go_back_or_whose_points_do_not_match_them_is_refused():
    with pytest.raises(ValueError, match="not decrease"):
        encode(JointTrajectory(np.array([1.0, 0.5]), np.zeros((2, 6))))
    with pytest.raises(ValueError, match="2 times and 1 points"):
        encode(JointTrajectory(np.array([1.0, 2.0]), np.zeros((1, 6))))
    good = JointTrajectory(np.array([0.5, 1.0]), np.ones((2, 6)))
    assert messages_equal(decode(encode(good)), good)


def test_expected_type_is_enforced_and_plain_view_is_json_ready():
    import json

    payload = encode(Twist(0.5, 0.1))
    with pytest.raises(DecodeError, match="expected JointState, got Twist"):
        decode(payload, JointState)
    plain = to_plain(decode(payload))
    assert json.loads(json.dumps(plain))["v"] == 0.5


def test_messages_are_frozen_values():
    js = JointState(["a"], [1.0], [0.0])
    with pytest.raises(ValueError, match="read-only"):
        js.q[0] = 2.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        js.names = ("b",)


def test_installed_packages_message_types_are_loaded_by_entry_point():
    from fabric.codec import load_plugins, registered

    load_plugins()
    assert {"WorldInfo", "IKStream", "IKRequest", "PlanRequest", "MapReply", "OwnRequest"} <= set(registered())
