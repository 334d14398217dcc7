"""The path follower reaches the end of any reasonable path, facing its direction of travel."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
import pytest

import robots
from sim_peer.controllers import BaseController
from sim_peer.physics.pure_pursuit import PurePursuit

BASE = robots.load("reeman").base


def densify(points: np.ndarray, step: float = 0.05) -> np.ndarray:
    out = [points[0]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.extend(a + (b - a) * (i / n) for i in range(1, n + 1))
    return np.array(out)


def drive(xs, ys, theta=None, seconds: float = 60.0, dt: float = 0.01):
    b = BaseController(BASE)
    b.follow(PurePursuit(xs, ys, theta, max_speed=BASE.max_speed, max_omega=BASE.max_omega, max_accel=BASE.max_accel))
    trace = []
    for _ in range(int(seconds / dt)):
        b.step(dt)
        trace.append((b.x, b.y, b.yaw, b.v))
        if b.follower is None and not b.moving:
            break
    return b, np.array(trace)


waypoints = st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), min_size=1, max_size=5)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(waypoints)
def test_any_polyline_is_followed_to_its_end(points):
    pts = densify(np.array([(0.0, 0.0), *points]))
    b, trace = drive(pts[:, 0], pts[:, 1])
    assert b.follower is None and b.paths_done == 1
    assert math.hypot(b.x - pts[-1, 0], b.y - pts[-1, 1]) < 0.1
    assert np.all(trace[:, 3] >= -1e-12)  # never reverses: it turns to face where it goes


def test_final_heading_is_the_paths_last_theta():
    xs = np.linspace(0, 2, 41)
    b, _ = drive(xs, np.zeros_like(xs), np.full_like(xs, -math.pi / 2))
    assert abs(b.x - 2) < 0.1 and abs(b.yaw + math.pi / 2) < 0.05


def test_a_path_that_passes_its_own_end_on_the_way_out_is_driven_in_full():
    pts = densify(
        np.array([(0.0, 0.0), (0.0, -2.0), (0.0, -1.0)])
    )  # found by hypothesis: it used to stop at y = -1 outbound
    b, trace = drive(pts[:, 0], pts[:, 1])
    assert trace[:, 1].min() < -1.9 and math.hypot(b.x, b.y + 1.0) < 0.1


def test_a_path_that_doubles_back_is_not_shortcut():
    out = np.linspace(0, 2, 41)
    xs = np.concatenate([out, out[::-1][1:]])
    ys = np.concatenate([np.zeros(41), np.full(40, 0.6)])
    ys[41:] = 0.6
    pts = densify(np.column_stack([xs, ys]))
    _, trace = drive(pts[:, 0], pts[:, 1])
    assert trace[:, 0].max() > 1.85  # went out to the far end before coming back
