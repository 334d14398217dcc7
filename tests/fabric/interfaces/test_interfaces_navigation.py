"""The navigation service messages round-trip through the fabric codec, and malformed ones are refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabric.interfaces import (
    DIRECTIONS,
    MAP_ACTIONS,
    PLANNER_NAMES,
    MapReply,
    MapRequest,
    PlanReply,
    PlanRequest,
    empty_grid,
)
from fabric.codec import DecodeError, decode, encode, messages_equal
from fabric.interfaces import Header, OccupancyGrid, Path

finite = st.floats(-1e6, 1e6, allow_nan=False)
ids = st.text(st.characters(whitelist_categories=("Ll", "Lu", "Nd")), min_size=1, max_size=12)
pose3 = st.one_of(st.just([]), st.lists(finite, min_size=3, max_size=3))
headers = st.builds(Header, stamp=finite, wall_ns=st.integers(0, 2**62), seq=st.integers(0, 2**31), source=ids)


@settings(max_examples=60, deadline=None)
@given(
    ids,
    pose3,
    pose3,
    st.sampled_from(PLANNER_NAMES),
    ids,
    st.sampled_from(DIRECTIONS),
    st.floats(0, 100),
    st.floats(0, 100),
    headers,
)
def test_plan_request_round_trip(robot, goal, start, planner, map_name, direction, turn, radius, header):
    msg = PlanRequest(robot, goal, start, planner, map_name, direction, turn, radius, header)
    assert messages_equal(decode(encode(msg)), msg)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 200), finite, st.integers(0, 10**6), headers)
def test_plan_reply_round_trip(n, value, expansions, header):
    x = np.linspace(0.0, value, n)
    path = Path(x, x * 0.5, np.zeros(n), "world", header)
    msg = PlanReply(path, "base1", "ompl:bitstar", 0.012, abs(value), expansions, "map", header)
    assert messages_equal(decode(encode(msg)), msg)


@settings(max_examples=40, deadline=None)
@given(
    st.sampled_from(MAP_ACTIONS), ids, st.floats(0, 1), st.integers(0, 30), st.integers(0, 30), st.integers(0, 10**6)
)
def test_map_messages_round_trip(action, name, threshold, h, w, scans):
    cells = np.random.default_rng(h * 31 + w).choice(np.array([0, 50, 100, 255], np.uint8), size=(h, w))
    grid = OccupancyGrid(0.05, np.array([1.0, -2.0, 0.0]), cells)
    req = MapRequest(action, name, threshold, "f.npz", grid)
    rep = MapReply(action, name, grid, scans, 1, "f.npz")
    assert messages_equal(decode(encode(req)), req)
    assert messages_equal(decode(encode(rep)), rep)


@pytest.mark.parametrize(
    "msg, match",
    [
        (PlanRequest("base1", goal=[math.nan, 0.0, 0.0]), "not finite"),
        (PlanRequest("base1", start=[0.0, math.inf, 0.0]), "not finite"),
        (PlanRequest("base1", turning_radius=-1.0), "outside"),
        (MapRequest("build", threshold=1.5), "outside"),
    ],
)
def test_bad_values_are_refused_by_the_decoder(msg, match):
    with pytest.raises(DecodeError, match=match):
        decode(encode(msg))


def test_wrong_shapes_and_names_are_refused():
    with pytest.raises(ValueError, match="empty or"):
        encode(PlanRequest("base1", goal=[1.0, 2.0]))
    raw = encode(PlanRequest("base1", goal=[1.0, 2.0, 3.0])).replace(b"hybrid_astar", b"hybrid_astaX")
    with pytest.raises(DecodeError, match="planner"):
        decode(raw)
    assert empty_grid().cells.shape == (0, 0)
