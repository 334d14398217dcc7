"""``robofabric bench class-nav``: its layout (pure), its report and budget line (pure, planted results), and one
small real class (2 students, slow). The figures come from the bench itself (docs/benchmarks.md); the real run here
checks only what must hold at any load: every field is there, no base bumped, no map kept a robot."""

from __future__ import annotations

import itertools
import math

import pytest

from robofabric.bench.class_nav import NO_RESULT, SLOTS, goal_of, placements, row, run_one, summary, verdict

SHELVES = [
    (-2.5, 2.5, 1.5, 0.3),
    (2.5, 2.5, 1.5, 0.3),
    (-2.5, -2.5, 1.5, 0.3),
    (2.5, -2.5, 1.5, 0.3),
    (0.0, -1.5, 0.2, 0.2),
]
"""The warehouse's shelves and pillar (robots/scenes/warehouse.xml): centre x, y and half sizes."""


def _student(**over) -> dict:
    good = {
        "plans": [0.2],
        "reached": True,
        "stops": 1,
        "collisions": 0,
        "blocked": 0,
        "robot_cells": 0,
        "errors": [],
        "final": 0.02,
        "notes": [],
        "said": [],
    }
    return {**good, **over}


@pytest.mark.parametrize("n", range(1, 9))
def test_every_goal_is_free_apart_off_the_lane_and_seen_from_its_start_through_the_gap(n):
    starts = placements(n)
    goals = [goal_of(i, s, n) for i, s in enumerate(starts)]
    for (x, y, yaw), (sx, _, _) in zip(goals, starts):
        assert abs(x) in SLOTS and yaw == (0.0 if x > 0 else math.pi)
        assert 5.0 - abs(y) >= 0.5 and abs(y) - 2.8 >= 1.5  # the wall 0.5 m off; a lane to the shelves
        assert min(math.hypot(max(abs(x - cx) - hx, 0), max(abs(y - cy) - hy, 0)) for cx, cy, hx, hy in SHELVES) > 0.6
        for face in (2.2, 2.8):  # her map knows the aisle only through the gap: the line to the goal passes it
            at = sx + (x - sx) * face / abs(y)
            assert abs(at) <= 1.0 - 0.1, (sx, x, face, at)
    for a, b in itertools.combinations(goals, 2):
        assert math.hypot(a[0] - b[0], a[1] - b[1]) >= 1.3
    north = [(s[0], g[0]) for s, g in zip(starts, goals) if g[1] > 0]
    assert any(sx < 0 < gx for sx, gx in north) == (len(north) > 1)  # paths cross in the gap once two go north
    assert len({g[:2] for g in goals}) == n


def test_the_report_counts_what_the_students_saw_and_the_budget_line_says_what_missed():
    good = summary(2, [_student(), _student(stops=2, plans=[0.1, 0.3])], 50.0)
    assert (good["n"], good["reached"], good["plans"], good["stops"], good["collisions"], good["cells"]) == (
        2,
        2,
        3,
        3,
        0,
        [0, 0],
    )
    assert verdict(good) == "2 bases: budget met"
    assert row(good).startswith("| 2 | 2/2 | 3, ")
    bumped = summary(2, [_student(), _student(collisions=1)], 50.0)  # a collision planted: counted, and fails
    assert bumped["collisions"] == 1 and verdict(bumped) == "2 bases: budget not met: 1 collisions"
    short = summary(2, [_student(), _student(reached=False, final=0.4)], 50.0)
    assert short["reached"] == 1 and verdict(short) == "2 bases: budget not met: 1 of 2 short of their goals"
    kept = summary(2, [_student(), _student(robot_cells=3)], 50.0)
    assert "robot cells" in verdict(kept)
    lost = summary(2, [_student(), dict(NO_RESULT)], 50.0)  # a student who wrote nothing is no pass
    assert lost["reached"] == 1 and lost["errors"] == ["no result"] and "not met" in verdict(lost)


@pytest.mark.slow
def test_two_students_do_test_b_at_once(tmp_path):
    r = run_one(2, tmp_path)
    assert set(r) >= {
        "n",
        "reached",
        "plans",
        "plan_p50",
        "plan_p99",
        "stops",
        "blocked",
        "collisions",
        "cells",
        "finals",
        "seconds",
        "errors",
        "notes",
        "said",
    }
    assert r["n"] == 2 and len(r["cells"]) == 2 and len(r["finals"]) == 2
    assert r["plans"] >= 1, r["errors"]  # at least one student planned
    assert r["collisions"] == 0, r["said"]  # the bumper never had to: bases keep apart, whatever the load
    assert r["cells"] == [0, 0], r  # each map was built and holds no robot
    assert all(f is not None for f in r["finals"]), r["errors"]  # each student saw her base to the end
    assert verdict(r).startswith("2 bases: budget ")
