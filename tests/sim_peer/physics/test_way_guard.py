"""Bases that meet do not collide: the way guard's decision (pure) and two real bases driven at each other (issue 44)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from fabric.interfaces import EventKind
from robots import SceneRobot
from sim_peer.physics.traffic import GIVE_WAY_AFTER
from sim_peer.physics.way_guard import (
    BACK_OFF,
    BACK_SPEED,
    BASE_CLEARANCE,
    BLOCKED_AFTER,
    RESUME,
    WAY_MARGIN,
    WayState,
    base_gap,
    decide,
    facing_forwards,
    trail_back,
    way_cap,
    way_gap,
)
from sim_peer.physics.world import SimWorld


def _line(x0: float, x1: float, n: int = 41) -> np.ndarray:
    return np.column_stack([np.linspace(x0, x1, n), np.zeros(n)])


def test_the_gap_is_the_path_run_before_the_disk_touches_a_hit():
    path = _line(0.0, 4.0)  # 0.1 m apart
    assert way_gap(path, np.array([[2.0, 0.0]]), 0.25) == pytest.approx(1.7)  # the disk about 1.8 would hold it
    assert way_gap(path, np.array([[2.0, 0.3]]), 0.25) == math.inf  # beside the path, clear of the disk
    assert way_gap(path, np.array([[5.0, 0.0]]), 0.25) == math.inf  # beyond the path's end
    assert way_gap(path, np.array([[0.1, 0.1]]), 0.25) == math.inf  # within the disk where it stands: the bumper's
    assert way_gap(path, np.zeros((0, 2)), 0.25) == math.inf
    turn = np.column_stack([np.cos(np.linspace(-math.pi / 2, 0, 30)), 1 + np.sin(np.linspace(-math.pi / 2, 0, 30))])
    assert way_gap(turn, np.array([[1.0, 1.0]]), 0.2) < math.inf  # on the curve, not straight ahead
    assert way_gap(turn, np.array([[1.6, 0.0]]), 0.2) == math.inf  # straight ahead, but the path turns away


@settings(max_examples=100, deadline=None)
@given(gap=st.floats(0.0, 5.0), accel=st.floats(0.1, 3.0))
def test_the_cap_brakes_to_a_stop_the_margin_short(gap, accel):
    v = way_cap(gap, accel)
    assert v >= 0.0
    assert v * v / accel <= max(gap - WAY_MARGIN, 0.0) + 1e-9  # braking at half its limit fits in what is left
    assert way_cap(math.inf, accel) == math.inf


@settings(max_examples=200, deadline=None)
@given(gaps=st.lists(st.tuples(st.floats(0.01, 1.0), st.floats(0.0, 2.0)), min_size=1, max_size=60))
def test_waiting_resuming_and_blocked(gaps):
    state, now, said = WayState(), 0.0, []
    for dt, gap in gaps:
        now += dt
        before = state
        state, news = decide(state, now, gap)
        said.append(news)
        if news == "waiting":
            assert before.waiting_since is None and gap <= WAY_MARGIN and state.waiting_since == now
        elif news == "resumed":
            assert before.waiting_since is not None and gap > WAY_MARGIN + RESUME and state.waiting_since is None
        elif news == "blocked":
            assert now - before.waiting_since >= BLOCKED_AFTER and state.waiting_since is None
        else:
            assert state == before  # nothing new: nothing changes
            if before.waiting_since is None:
                assert gap > WAY_MARGIN
    # what is said alternates: a wait ends (resumed, blocked) before another begins
    events = [n for n in said if n]
    assert all((a == "waiting") != (b == "waiting") for a, b in zip(events, events[1:]))


def test_two_bases_driven_at_each_other_stop_apart_say_so_and_one_gives_way():
    world = SimWorld("warehouse", [SceneRobot("reeman", "base2", (2.0, 0.0, 0.0, math.pi))], seed=1)
    b1, b2 = world.robots["base1"], world.robots["base2"]
    b1.path(np.linspace(0.0, 2.0, 41), np.zeros(41), np.zeros(41))  # each to where the other stands
    b2.path(np.linspace(2.0, 0.0, 41), np.zeros(41), np.full(41, math.pi))
    notes, closest = [], math.inf

    def run(seconds: float) -> None:
        nonlocal notes, closest
        for _ in range(int(seconds / world.dt / 50)):
            world.step(50)
            notes += world.notes.take()
            closest = min(closest, math.hypot(b1.ctrl.x - b2.ctrl.x, b1.ctrl.y - b2.ctrl.y))

    def stops() -> list[tuple[str, str]]:
        return [(rid, n.reason) for rid, n in notes if n.kind == EventKind.OBSTACLE_STOP]

    run(3.0)  # their ways meet at once: one lets the other through first (base2: a tie, the greater id) and waits
    # short of its way; the other comes on and stops before it, both within 3 s
    assert sorted(stops()) == [("base1", "waiting"), ("base2", "waiting")]  # each said so
    first = [rid for rid, n in notes if n.kind == EventKind.OBSTACLE_STOP]
    assert first[0] == "base2" and abs(b2.ctrl.x - 2.0) < 0.2  # it yielded where it stood
    assert not [n for _, n in notes if n.kind == EventKind.COLLISION]  # the bumper never had to
    assert closest > 2 * 0.25  # their chassis never met
    assert abs(b1.ctrl.v) < 1e-6 and abs(b2.ctrl.v) < 1e-6  # both wait, paths kept
    assert b1.ctrl.follower is not None and b2.ctrl.follower is not None
    assert b1.guard.blocker == "base2" and b2.guard.blocker == "base1"  # each names the other
    # they wait for each other: after GIVE_WAY_AFTER one of them, the later waiter (the greater id on a tie), gives
    # way: it backs off along the way it came (BACK_OFF at BACK_SPEED), then says blocked
    began = {rid: (n.data["t"], rid) for rid, n in notes if n.kind == EventKind.OBSTACLE_STOP and n.reason == "waiting"}
    yielder = max(began, key=began.__getitem__)
    keeper = "base1" if yielder == "base2" else "base2"
    y, k = world.robots[yielder], world.robots[keeper]
    stood = y.ctrl.x
    run(GIVE_WAY_AFTER + BACK_OFF / BACK_SPEED + 1.0)
    gave = [(rid, n.data) for rid, n in notes if n.kind == EventKind.OBSTACLE_STOP and n.reason == "blocked"]
    assert [(rid, data["gave_way_to"]) for rid, data in gave] == [(yielder, keeper)], stops()
    assert f"gave way to {keeper}" in gave[0][1]["detail"] and "backed off" in gave[0][1]["detail"]
    away = 1.0 if yielder == "base2" else -1.0  # base2 came from +x, base1 from -x
    assert away * (y.ctrl.x - stood) > 0.75 * BACK_OFF  # backwards, the way it came
    assert y.ctrl.follower is None and k.ctrl.follower is not None  # the other keeps its path
    assert y.ctrl.paths_done == 0 and not [
        n for _, n in notes if n.kind == EventKind.PATH_DONE
    ]  # no path of its user's done
    assert yielder not in world.traffic.waiters
    # it stands where it backed off to (its user plans again): the other comes on and stops before it again, and after
    # BLOCKED_AFTER drops its path and reports blocked as before
    run(BLOCKED_AFTER + 2.0)
    assert [r for r in stops() if r[1] == "blocked"] == [(yielder, "blocked"), (keeper, "blocked")]
    assert k.ctrl.follower is None and not [n for _, n in notes if n.kind == EventKind.COLLISION]
    assert closest > 2 * 0.25


def test_the_way_back_is_the_way_it_came_driven_backwards():
    points = np.column_stack([np.linspace(0.0, 2.0, 21), np.zeros(21)])  # 0.1 m apart, along +x
    trail = trail_back(points, 10, np.array([1.02, 0.0]), 0.4)
    assert trail is not None and trail[0].tolist() == [1.02, 0.0] and trail[-1] == pytest.approx([0.62, 0.0])
    assert (np.diff(trail[:, 0]) < 0).all()  # back along -x
    headings = facing_forwards(trail, 0.0)
    assert np.allclose(headings, 0.0)  # facing the way the path ran: a backwards stretch for the follower
    assert trail_back(points, 0, np.array([0.0, 0.0]), 0.4) is None  # no way behind it
    short = trail_back(points, 2, np.array([0.2, 0.0]), 0.4)
    assert short is not None and short[-1].tolist() == [0.0, 0.0]  # what there is of it


def test_a_base_waits_for_a_base_crossing_its_way_and_goes_on():
    world = SimWorld("warehouse", [SceneRobot("reeman", "base2", (1.2, 0.0, 0.0, math.pi / 2))], seed=1)
    b1 = world.robots["base1"]
    b1.path(np.linspace(0.0, 2.0, 41), np.zeros(41), np.zeros(41))
    notes = []
    for _ in range(int(2.0 / world.dt / 50)):
        world.step(50)
        notes += world.notes.take()
    assert [n.reason for _, n in notes if n.kind == EventKind.OBSTACLE_STOP] == ["waiting"]
    assert b1.ctrl.x < 1.2 - 0.5  # stopped short of base2
    world.robots["base2"].twist(0.8, 0.0)  # base2 drives off the way
    for _ in range(int(6.0 / world.dt / 50)):
        world.step(50)
        notes += world.notes.take()
        if b1.ctrl.follower is None:
            break
    assert [n.reason for _, n in notes if n.kind == EventKind.OBSTACLE_STOP] == ["waiting", "resumed"]
    assert math.hypot(b1.ctrl.x - 2.0, b1.ctrl.y) < 0.1  # and reached the end of its path


def test_a_bumper_stop_names_the_base_it_stopped_before():
    world = SimWorld("warehouse", [SceneRobot("reeman", "base2", (1.0, 0.0, 0.0, math.pi))], seed=1)
    world.robots["base1"].twist(0.5, 0.0)  # driven by hand at a parked base: no path, no guard, only the bumper
    for _ in range(40):
        world.step(50)
    said = [(rid, n.data) for rid, n in world.notes.take() if n.kind == EventKind.COLLISION]
    assert said and said[0][0] == "base1" and said[0][1]["what"] == "base2"
    assert said[0][1]["detail"].startswith("stopped before base2 ahead at (")


def test_another_base_within_reach_may_be_left_never_neared():
    path = _line(0.0, 4.0)
    assert base_gap(path, (2.0, 0.0), 0.65) == pytest.approx(1.3)  # up to x = 1.3, 0.7 from it
    assert base_gap(path, (2.0, 0.7), 0.65) == math.inf  # the path passes it 0.7 off
    assert base_gap(path, (0.3, 0.3), 0.65) == 0.0  # beside it already, and the path leads nearer: no way on
    assert base_gap(path, (-0.3, 0.0), 0.65) == math.inf  # behind it: the path leads away


@settings(max_examples=200, deadline=None)
@given(
    pts=st.lists(st.tuples(st.floats(-2, 2), st.floats(-2, 2)), min_size=2, max_size=20),
    centre=st.tuples(st.floats(-2, 2), st.floats(-2, 2)),
    radius=st.floats(0.1, 1.5),
)
def test_up_to_the_gap_a_base_never_comes_nearer_another_than_its_reach_or_than_it_stands(pts, centre, radius):
    path = np.array(pts)
    gap = base_gap(path, centre, radius)
    d = np.hypot(path[:, 0] - centre[0], path[:, 1] - centre[1])
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    before = d[1:][arc[1:] <= gap] if math.isfinite(gap) else d[1:]
    assert (before >= min(radius, d[0]) - 1e-9).all()
    if math.isfinite(gap):  # and the point after it does
        assert (d[1:][arc[1:] > gap] < min(radius, d[0])).any()


@pytest.mark.parametrize("later", [0.0, 0.4])
def test_two_bases_crossing_stop_apart_and_both_get_through(later):
    """Two paths that cross at an angle (as in the warehouse's gap): each base sees the other come from the side too
    late for the check of where it stands (before: both stopped 0.1 m short and met on the bumper, centres 0.59 m
    apart); the one further from the meeting lets the other through first."""
    a0, a1, b0, b1 = (-1.5, 0.0), (1.5, 1.8), (1.5, 0.0), (-1.5, 1.8)
    world = SimWorld("warehouse", [SceneRobot("reeman", "base2", (*b0, 0.0, math.atan2(1.8, -3.0)))], seed=1)
    r1, r2 = world.robots["base1"], world.robots["base2"]
    r1.ctrl.x, r1.ctrl.y, r1.ctrl.yaw = *a0, math.atan2(1.8, 3.0)

    def line(a, b):
        return (
            np.linspace(a[0], b[0], 61),
            np.linspace(a[1], b[1], 61),
            np.full(61, math.atan2(b[1] - a[1], b[0] - a[0])),
        )

    r1.path(*line(a0, a1))
    notes, closest, started = [], math.inf, False
    while world.time < 12.0 and not (started and r1.ctrl.follower is None and r2.ctrl.follower is None):
        world.step(25)
        if not started and world.time >= later:
            r2.path(*line(b0, b1))
            started = True
        notes += world.notes.take()
        closest = min(closest, math.hypot(r1.ctrl.x - r2.ctrl.x, r1.ctrl.y - r2.ctrl.y))
    assert not [(rid, n.data) for rid, n in notes if n.kind == EventKind.COLLISION]
    assert closest > 2 * 0.3 + BASE_CLEARANCE  # their disks never came within the clearance
    assert sorted(rid for rid, n in notes if n.kind == EventKind.PATH_DONE) == ["base1", "base2"]  # both got through


def test_a_waiting_base_holds_until_it_says_resumed():
    """Its way opening within the resume band lets it go on no more than its words do (two waiting bases crept 0.1 m
    each, unsaid, into each other's bumper)."""
    world = SimWorld("warehouse", [SceneRobot("reeman", "base2", (2.0, 0.0, 0.0, 0.0))], seed=1)
    b1, b2 = world.robots["base1"], world.robots["base2"]
    b1.path(np.linspace(0.0, 3.0, 301), np.zeros(301), np.zeros(301))  # 1 cm apart: the gap to the centimetre
    notes = []
    for _ in range(60):
        world.step(25)
        notes += world.notes.take()
    assert [n.reason for _, n in notes if n.kind == EventKind.OBSTACLE_STOP] == ["waiting"]
    stood = b1.ctrl.x
    b2.ctrl.x += WAY_MARGIN + RESUME / 2 - b1.guard.gap  # the gap opens to within the band, not beyond it
    world.step(25)  # the board has base2's new spot from this step on
    for _ in range(40):
        world.step(25)
        notes += world.notes.take()
        assert WAY_MARGIN < b1.guard.gap <= WAY_MARGIN + RESUME
    assert b1.ctrl.x == pytest.approx(stood, abs=1e-3) and "resumed" not in [n.reason for _, n in notes]
    b2.ctrl.x += 1.0  # now it clears
    for _ in range(40):
        world.step(25)
        notes += world.notes.take()
    assert "resumed" in [n.reason for _, n in notes] and b1.ctrl.x > stood + 0.2
