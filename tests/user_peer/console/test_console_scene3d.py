"""The 3D view's numbers (:mod:`user_peer.console.scene3d`): a link's cylinder pose, an arm's frames in the world,
the scene's boxes with their orientation."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from user_peer.console.scene3d import arm_points, quat_matrix, scene_boxes3d, segment_pose
from user_peer.console.state import arm_chain

coord = st.floats(-3.0, 3.0, allow_nan=False)


@settings(deadline=None)  # a loaded machine, not the function, made a first example slow
@given(st.tuples(coord, coord, coord), st.tuples(coord, coord, coord))
def test_a_cylinder_of_height_one_posed_by_segment_pose_spans_its_segment(a, b):
    mid, R, n = segment_pose(a, b)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and math.isclose(np.linalg.det(R), 1.0, abs_tol=1e-9)
    if n > 1e-6:  # its local y axis scaled by the length: its ends are a and b
        assert np.allclose(mid + R @ np.array([0.0, n / 2, 0.0]), b, atol=1e-9)
        assert np.allclose(mid - R @ np.array([0.0, n / 2, 0.0]), a, atol=1e-9)


def test_an_arm_is_placed_at_its_spawn_pose_and_turned_by_its_yaw():
    chain = arm_chain("meca500")
    q = np.radians([10, -20, 30, 0, 45, 0])
    local = chain.origins(q)
    pts = arm_points("meca500", q, (1.0, 2.0, 0.5, math.pi / 2))
    assert np.allclose(pts[0], (1.0, 2.0, 0.5))  # the base first
    assert np.allclose(pts[1:], np.stack([1.0 - local[:, 1], 2.0 + local[:, 0], 0.5 + local[:, 2]], axis=1))


def test_an_arm_whose_joints_do_not_fit_its_chain_has_no_points():
    assert arm_points("meca500", [0.0, 0.0], (0, 0, 0, 0)).shape == (0, 3)
    assert arm_points("no-such-arm", [0.0] * 6, (0, 0, 0, 0)).shape == (0, 3)


def test_a_quaternion_turning_a_quarter_about_z_maps_x_to_y():
    s = math.sqrt(0.5)
    assert np.allclose(quat_matrix((0.0, 0.0, s, s)) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])


def test_the_combined_scenes_walls_and_shelves_without_the_floor():
    boxes = scene_boxes3d("combined")
    names = {b.name for b in boxes}
    assert "wall_n" in names and all(b.size[2] >= 0.02 for b in boxes)
    wall = next(b for b in boxes if b.name == "wall_n")
    assert wall.center[1] > 4.0 and wall.size[0] > 10.0
