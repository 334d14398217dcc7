"""The viewer's pure geometry (user_peer.geometry): quaternion algebra checked against rotation matrices,
and the logger drawing with these very helpers (one definition, re-exported by user_peer.rerun_log)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from user_peer import geometry as g
from user_peer import rerun_log
from user_peer.arm_geometry import Placement

_unit = (
    st.lists(st.floats(-1, 1), min_size=4, max_size=4)
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: np.asarray(v) / np.linalg.norm(v))
)
_vec = st.lists(st.floats(-3, 3), min_size=3, max_size=3).map(np.asarray)


@settings(max_examples=60, deadline=None)
@given(_unit, _unit)
def test_the_product_of_quaternions_rotates_as_the_product_of_their_matrices(a, b):
    r = g.rotation_xyzw(g.quat_mul_xyzw(a, b))
    assert np.allclose(r, g.rotation_xyzw(a) @ g.rotation_xyzw(b), atol=1e-9)
    assert np.allclose(r.T @ r, np.eye(3), atol=1e-9) and math.isclose(np.linalg.det(r), 1.0, abs_tol=1e-9)


@settings(max_examples=60, deadline=None)
@given(_unit, _vec, _unit, _vec)
def test_compose_maps_a_point_as_base_after_placement(qb, tb, qp, tp):
    base, p = Placement(tb, qb), Placement(tp, qp)
    t, q = g.compose(base, p)
    point = np.array([0.3, -0.2, 0.5])
    direct = tb + g.rotation_xyzw(qb) @ (tp + g.rotation_xyzw(qp) @ point)
    assert np.allclose(t + g.rotation_xyzw(np.asarray(q)) @ point, direct, atol=1e-9)
    alone_t, alone_q = g.compose(None, p)  # no base: the placement itself
    assert np.allclose(alone_t, tp) and np.allclose(alone_q, qp)


def test_wxyz_to_xyzw_and_yaw():
    half = math.radians(30)
    q = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])  # 60 degrees about z, (w, x, y, z)
    assert g.quat_xyzw(q) == [0.0, 0.0, math.sin(half), math.cos(half)]
    assert math.isclose(g.yaw_of(q), math.radians(60))


def test_the_logger_draws_with_the_same_helpers():
    for name in (
        "scan_world_points",
        "grid_rgb",
        "world_to_map_pixels",
        "yaw_of",
        "shown_position",
        "EXTRAPOLATION_CAP_S",
    ):
        assert getattr(rerun_log, name) is getattr(g, name), name
