"""Starts and goals near obstacles recover, as Nav2's planners do: an escape move from a start inside the
inflation, a goal moved out of an obstacle, and refusals that name the obstacle (issue 44)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from compute_peer.navigation import (
    NavigationError,
    PlannerSettings,
    VehicleModel,
    build_costmap,
    path_collision,
    plan_path,
)
from compute_peer.navigation.grid import make_grid
from compute_peer.navigation.recovery import RecoverySettings, nearest_obstacle, recover

RES = 0.05
RADIUS = 0.3
SETTINGS = PlannerSettings(vehicle=VehicleModel(robot_radius=RADIUS, turning_radius=0.5))


def _room() -> np.ndarray:
    """A 6 m x 4 m room (walls 0.1 m) with a 1 m x 1 m shelf whose faces are x = 2.5, 3.5 and y = 1.5, 2.5."""
    cells = np.zeros((80, 120), dtype=np.uint8)
    cells[:2, :] = cells[-2:, :] = cells[:, :2] = cells[:, -2:] = 100
    cells[30:50, 50:70] = 100
    return cells


@pytest.fixture(scope="module")
def costmap():
    return build_costmap(make_grid(_room(), RES), RADIUS)


def _clearance(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest occupied cell centre of the room."""
    rows, cols = np.nonzero(_room() == 100)
    ox, oy = (cols + 0.5) * RES, (rows + 0.5) * RES
    return np.array([np.hypot(ox - a, oy - b).min() for a, b in zip(x, y)])


@pytest.mark.parametrize("planner", ["hybrid_astar", "ompl"])
def test_a_start_in_the_inflation_plans_with_an_escape_move(costmap, planner):
    start = (2.3, 2.0, 0.0)  # facing the shelf's face at x = 2.5: 0.175 m from its cell centres, radius 0.3
    assert costmap.clearance_reason(*start[:2], "start") is not None
    result = plan_path(costmap, start, (5.0, 3.5, 0.0), planner=planner, settings=SETTINGS)
    assert (result.x[0], result.y[0]) == pytest.approx(start[:2])
    assert (result.x[-1], result.y[-1]) == pytest.approx((5.0, 3.5))
    assert re.search(
        r"an obstacle or unknown space at \(2\.5\d, [12]\.\d\d\), 0\.2\d m away: the path first drives 0\.\d\d m",
        result.note,
    )
    # the escape move never brings the robot nearer to the shelf than it stood; then the path is clear
    here = _clearance(np.array([start[0]]), np.array([start[1]]))[0]
    clear = _clearance(result.x, result.y)
    first_free = int(np.flatnonzero(costmap.free(result.x, result.y))[0])
    assert (clear[: first_free + 1] >= here - 1e-9).all()
    assert np.hypot(np.diff(result.x[: first_free + 1]), np.diff(result.y[: first_free + 1])).sum() <= 0.5 + 1e-9
    assert path_collision(costmap, result.x[first_free:], result.y[first_free:]) is None
    assert (clear[first_free:] >= RADIUS - 1e-9).all()


def test_a_start_that_cannot_escape_is_refused_naming_the_obstacle():
    cells = np.zeros((40, 40), dtype=np.uint8)
    cells[:, :2] = cells[:, -2:] = cells[:2, :] = cells[-2:, :] = 100
    cells[:, 19:21] = (
        100  # a middle wall: 0.85 m between it and the left wall, nowhere 0.6 m (radius + margin) from both
    )
    costmap = build_costmap(make_grid(cells, RES), RADIUS, margin=0.3)  # a margin no short move gets out of
    with pytest.raises(
        NavigationError,
        match=r"start \(0\.35, 1\.00\) is within the robot radius \(0\.30 m\) of an "
        r"obstacle or unknown space at \(0\.\d\d, \d\.\d\d\), 0\.\d\d m away",
    ):
        plan_path(costmap, (0.35, 1.0, 0.0), (1.4, 1.0, 0.0), settings=SETTINGS)


@pytest.mark.parametrize("planner", ["hybrid_astar", "ompl"])
def test_a_goal_inside_an_obstacle_is_moved_to_the_nearest_free_pose_and_said(costmap, planner):
    goal = (3.0, 1.45, math.pi / 2)  # just inside the shelf's lower face
    result = plan_path(costmap, (1.0, 1.0, 0.0), goal, planner=planner, settings=SETTINGS)
    end = (float(result.x[-1]), float(result.y[-1]))
    assert end[0] == pytest.approx(3.0, abs=RES) and end[1] < 1.5 - RADIUS  # below the shelf, where it fits
    assert math.hypot(end[0] - goal[0], end[1] - goal[1]) <= 0.5
    assert result.note.startswith("goal moved") and f"({end[0]:.2f}, {end[1]:.2f})" in result.note
    assert result.theta[-1] == pytest.approx(goal[2])
    with pytest.raises(
        NavigationError,
        match=r"goal \(3\.00, 2\.00\) is inside an obstacle .* no pose where the robot fits lies within 0\.50 m",
    ):
        plan_path(costmap, (1.0, 1.0, 0.0), (3.0, 2.0, 0.0), planner=planner, settings=SETTINGS)  # the shelf's middle


@hsettings(max_examples=40, deadline=None)
@given(x=st.floats(0.15, 5.85), y=st.floats(0.15, 3.85), theta=st.floats(-math.pi, math.pi))
def test_recovery_leaves_free_poses_alone_and_ends_where_the_robot_fits(x, y, theta):
    costmap = build_costmap(make_grid(_room(), RES), RADIUS)
    pose = (x, y, theta)
    free = costmap.free_xy(x, y)
    try:
        rec = recover(costmap, pose, pose)
    except NavigationError as exc:
        assert "obstacle" in str(exc)
        return
    assert costmap.clearance_reason(rec.goal[0], rec.goal[1], "goal", tight_ok=True) is None
    if costmap.clearance_reason(x, y, "goal", tight_ok=True) is None:
        assert rec.goal == pose and not rec.escape[0].size and not rec.notes  # nothing to recover from
    if free:
        assert rec.start == pose
    if rec.escape[0].size:
        assert costmap.free_xy(*rec.start[:2])


def test_nearest_obstacle_names_the_closest_cell(costmap):
    ox, oy, d = nearest_obstacle(costmap, 2.3, 2.0, 1.0)
    assert (ox, oy) == pytest.approx((2.525, 1.975)) or (ox, oy) == pytest.approx((2.525, 2.025))
    assert d == pytest.approx(math.hypot(0.225, 0.025))
    assert nearest_obstacle(costmap, 1.0, 1.0, 0.3) is None


def test_the_plan_service_says_what_it_recovered_from_in_the_reply(connect):
    """Over Zenoh, as a student asks: a start in the inflation plans, and the reply's note says how."""
    from compute_peer.navigation import register_navigation
    from fabric import keys
    from fabric.interfaces import MapRequest, PlanRequest, ServiceError
    from robofabric.testing import wait_until

    user = connect("user", "bob")
    with register_navigation(
        connect("compute", "compute-1"),
        robots=["base1"],
        settings=SETTINGS,
        sensor_offset=(0.0, 0.0, 0.0),
        discover=False,
    ) as nav:
        nav.map_service.handle(MapRequest("set", grid=make_grid(_room(), RES)))

        def ask(start, goal):
            try:
                return user.rpc.call(
                    keys.srv_asked(user.world, "plan", "base1", "bob"),
                    PlanRequest("base1", start=np.array(start), goal=np.array(goal)),
                    timeout=10.0,
                )
            except ServiceError as exc:
                return exc

        wait_until(
            lambda: not isinstance(ask((1.0, 1.0, 0.0), (5.0, 3.5, 0.0)), ServiceError) or None, what="plan service"
        )
        plain = ask((1.0, 1.0, 0.0), (5.0, 3.5, 0.0))
        assert plain.note == ""
        reply = ask((2.3, 2.0, 0.0), (5.0, 3.5, 0.0))
        assert "first drives" in reply.note and (reply.path.x[0], reply.path.y[0]) == pytest.approx((2.3, 2.0))
        refused = ask((1.0, 1.0, 0.0), (3.0, 2.0, 0.0))
        assert isinstance(refused, ServiceError) and "no pose where the robot fits" in refused.reason


def test_a_base_facing_a_wall_close_up_turns_on_the_spot_first(costmap):
    start = (2.1, 2.0, 0.0)  # 0.4 m from the shelf's face, facing it: every forward arc of Hybrid A* touches it
    assert costmap.free_xy(*start[:2])
    strict = PlannerSettings(vehicle=SETTINGS.vehicle, recovery=RecoverySettings(turn_in_place=False))
    with pytest.raises(NavigationError, match="cannot drive away from its start"):
        plan_path(costmap, start, (0.6, 3.4, math.pi), settings=strict)
    result = plan_path(costmap, start, (0.6, 3.4, math.pi), settings=SETTINGS)
    assert (result.x[0], result.y[0]) == pytest.approx(start[:2])
    assert abs(math.remainder(result.theta[0] - start[2], 2 * math.pi)) >= math.radians(90) - 1e-9  # turned first
    assert "first turns on the spot" in result.note
    assert path_collision(costmap, result.x, result.y) is None
