"""The plan service checks its inputs' ranges before computing: a robot radius past what a costmap is built for is a
clear refusal, never numpy's "operands could not be broadcast together" from inside the inflation (issue 42)."""

from __future__ import annotations

import numpy as np
import pytest

from compute_peer.navigation.costmap import MAX_INFLATION_CELLS, build_costmap
from compute_peer.navigation.errors import NavigationError
from compute_peer.navigation.grid import dilate, make_grid
from fabric.interfaces import MapRequest, PlanRequest
from test_nav_service import ROBOT, call, peers, refused  # noqa: F401  (peers: the service's fixture)


def _room() -> np.ndarray:
    cells = np.zeros((60, 60), dtype=np.uint8)
    cells[20:40, 20:40] = 100
    return cells


def test_a_radius_past_the_largest_inflation_is_refused_before_computing():
    grid = make_grid(_room(), 0.05)
    with pytest.raises(
        NavigationError,
        match=rf"robot radius 99.00 m is 1980 cells of this map \(0.050 m each\): at most {MAX_INFLATION_CELLS} cells",
    ):
        build_costmap(grid, 99.0)
    assert (
        build_costmap(grid, 0.25).collision.sum() > build_costmap(grid, 0.0).collision.sum()
    )  # an ordinary one still inflates


def test_an_inflation_wider_than_the_map_covers_it_and_fails_nowhere():
    mask = np.zeros((10, 40), dtype=bool)
    mask[5, 20] = True
    out = dilate(mask, 30.0)  # rows 30 away from the obstacle are past the map's 10 rows
    assert out.all()


@pytest.mark.slow
def test_the_plan_service_refuses_a_99_m_radius_with_its_reason_and_keeps_answering(peers):  # noqa: F811
    nav, _, user = peers
    call(user, "map", "map", MapRequest("set", grid=make_grid(_room(), 0.1)))
    reason = refused(
        user, "plan", ROBOT, PlanRequest(ROBOT, goal=[1.0, 1.0, 0.0], start=[0.5, 0.5, 0.0], robot_radius=99.0)
    )
    assert "robot radius 99.00 m is 990 cells" in reason and "broadcast" not in reason, reason
    plan = call(user, "plan", ROBOT, PlanRequest(ROBOT, goal=[1.0, 5.0, 0.0], start=[0.5, 0.5, 0.0], robot_radius=0.2))
    assert plan.length > 0
