"""Both planners: paths collision-free against the inflated map, within the turning radius, refusals with reasons."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from compute_peer.navigation import (
    HybridAStarConfig,
    NavigationError,
    OmplConfig,
    PlannerSettings,
    VehicleModel,
    build_costmap,
    path_collision,
    plan_path,
)
from compute_peer.navigation.costmap import densify
from compute_peer.navigation.dubins import dubins_paths
from compute_peer.navigation.grid import UNKNOWN, dilate, disk_offsets, make_grid
from compute_peer.navigation.recovery import RecoverySettings
from compute_peer.navigation.scenes import office
from navscenes import scene_clearance

RES = 0.05
ROBOT = 0.25
TURN = 0.6

CASES = [
    ((2.0, 2.0, 0.0), (18.0, 18.0, math.pi / 2)),  # through both partition gaps
    ((3.0, 17.0, 0.0), (17.0, 3.0, math.pi)),
    ((2.0, 10.0, math.pi / 2), (2.0, 6.0, math.pi / 2)),  # behind the start: a U-turn in a 5.5 m wide bay
]


@pytest.fixture(scope="module")
def scene():
    return office()


@pytest.fixture(scope="module")
def costmap(scene):
    return build_costmap(scene.rasterize(RES), ROBOT)


def settings(reverse: bool, ompl_planner: str = "rrtstar") -> PlannerSettings:
    return PlannerSettings(
        vehicle=VehicleModel(robot_radius=ROBOT, turning_radius=TURN, allow_reverse=reverse),
        # deadlines for a loaded box, not a pace: at load 12-26 this process has a tenth of a core, and 10 s of wall
        # failed case 0 (rrtstar, forward) twice, Hybrid A*'s default 5 s case 0 (reverse) once; each finds its
        # path in well under a second on a quiet box (Hybrid A*'s expansions stay bounded by max_expansions)
        hybrid=HybridAStarConfig(time_limit=60.0),
        ompl=OmplConfig(planner=ompl_planner, time_limit=60.0),
    )


def check_drivable(result, start, goal, reverse: bool) -> None:
    x, y, th = result.x, result.y, result.theta
    assert len(x) >= 2 and len(x) == len(y) == len(th)
    assert np.allclose([x[0], y[0]], start[:2]) and abs(math.remainder(th[0] - start[2], 2 * math.pi)) < 1e-6
    assert (
        np.allclose([x[-1], y[-1]], goal[:2], atol=1e-6) and abs(math.remainder(th[-1] - goal[2], 2 * math.pi)) < 1e-6
    )
    ds = np.hypot(np.diff(x), np.diff(y))
    assert ds.max() <= RES + 1e-9  # a pose at least every map cell
    dth = np.abs(np.remainder(np.diff(th) + math.pi, 2 * math.pi) - math.pi)
    moving = ds > 1e-6
    # the heading is the direction of travel (forwards) or its opposite (backwards)
    heading = np.stack([np.cos(th[:-1]), np.sin(th[:-1])])
    motion = np.stack([np.diff(x), np.diff(y)]) / np.maximum(ds, 1e-12)
    along = (heading * motion).sum(axis=0)
    # turning radius: the heading turns at most 1/R per metre driven. Poses are equally spaced in
    # driven distance, so no step may turn more than (spacing / R); on a step without a cusp the chord
    # is the distance driven (to within the tiny chord/arc slack) and the bound holds step by step.
    spacing = ds.max()
    assert (dth <= spacing / TURN * (1 + 1e-3) + 1e-9).all()
    plain = moving & (dth <= ds / TURN * (1 + 1e-3) + 1e-9)
    if reverse:
        # only steps that hold a cusp (driving forth and back within one step) may fail step by step
        assert plain.sum() >= 0.98 * moving.sum()
        assert (np.abs(along[plain]) > 0.99).all()
    else:
        assert plain.sum() == moving.sum()
        assert (along[moving] > 0.99).all()
    assert result.length == pytest.approx(ds.sum())


@pytest.mark.parametrize("planner", ["hybrid_astar", "ompl:rrtstar", "ompl:bitstar"])
@pytest.mark.parametrize("reverse", [False, True], ids=["forward", "reverse"])
@pytest.mark.parametrize("case", range(len(CASES)))
def test_paths_are_collision_free_and_drivable(scene, costmap, planner, reverse, case):
    start, goal = CASES[case]
    result = plan_path(costmap, start, goal, planner=planner, settings=settings(reverse))
    assert result.planner.startswith(planner)
    check_drivable(result, start, goal, reverse)
    # collision-free against the inflated map, densely sampled along the path...
    assert path_collision(costmap, result.x, result.y, step=RES / 10) is None
    # ...and against the true geometry of the scene: the robot's disk never reaches a wall
    xs, ys = densify(result.x, result.y, RES / 10)
    assert scene_clearance(scene, xs, ys).min() >= ROBOT - RES


@pytest.mark.slow
def test_ompl_means_the_configured_ompl_planner(costmap):
    start, goal = CASES[0]
    result = plan_path(costmap, start, goal, planner="ompl", settings=settings(False, "bitstar"))
    assert result.planner == "ompl:bitstar"
    result = plan_path(costmap, start, goal, planner="ompl", settings=settings(False, "rrtstar"))
    assert result.planner == "ompl:rrtstar"
    check_drivable(result, start, goal, False)
    assert path_collision(costmap, result.x, result.y) is None


def test_plan_on_a_grid_builds_the_costmap(scene):
    grid = scene.rasterize(RES)
    result = plan_path(grid, (2.0, 2.0, 0.0), (5.0, 2.0, 0.0), settings=settings(False))
    assert result.length == pytest.approx(3.0, abs=0.05)  # a straight line, found by the analytic shot


@pytest.mark.parametrize("planner", ["hybrid_astar", "ompl"])
@pytest.mark.parametrize(
    "start, goal, match",
    [
        ((2.0, 2.0, 0.0), (6.15, 5.0, 0.0), "goal .* inside an obstacle"),  # in the partition wall
        ((2.0, 2.0, 0.0), (6.5, 5.0, 0.0), "goal .* within the robot radius"),  # 0.225 m from the wall cells
        ((2.0, 2.0, 0.0), (25.0, 5.0, 0.0), "goal .* outside the map"),
        ((-1.0, 2.0, 0.0), (5.0, 5.0, 0.0), "start .* outside the map"),
        ((9.5, 4.5, 0.0), (5.0, 5.0, 0.0), "start .* inside an obstacle"),  # in a pillar
    ],
)
def test_bad_endpoints_are_refused_with_a_reason(costmap, planner, start, goal, match):
    strict = replace(settings(False), recovery=RecoverySettings(escape=0.0, goal_tolerance=0.0))  # no recovery
    with pytest.raises(NavigationError, match=match):
        plan_path(costmap, start, goal, planner=planner, settings=strict)


@pytest.mark.parametrize("planner", ["hybrid_astar", "ompl"])
@pytest.mark.parametrize("reverse", [False, True], ids=["forward", "reverse"])
@pytest.mark.parametrize("gap", [0.28, 0.32])
def test_start_and_goal_close_to_a_wall_are_accepted(scene, costmap, planner, reverse, gap):
    # both poses lie in cells whose centres are 0.30 m from the partitions' cells: the robot fits
    # (radius 0.25) but sits inside the planners' margin (0.32 m)
    start, goal = (6.275 + gap, 5.0, math.pi / 2), (13.025 - gap, 9.0, -math.pi / 2)
    assert not costmap.free_xy(*start[:2]) and not costmap.free_xy(*goal[:2])
    result = plan_path(costmap, start, goal, planner=planner, settings=settings(reverse))
    check_drivable(result, start, goal, reverse)
    assert path_collision(costmap, result.x, result.y) is None
    xs, ys = densify(result.x, result.y, RES / 10)
    assert scene_clearance(scene, xs, ys).min() >= ROBOT - RES


def test_unreachable_goal_is_refused_without_searching():
    cells = np.zeros((100, 100), dtype=np.uint8)
    cells[40:60, 40] = cells[40:60, 60] = cells[40, 40:61] = cells[60, 40:61] = 100  # a closed box
    grid = make_grid(cells, 0.1)
    with pytest.raises(NavigationError, match="cannot be reached"):
        plan_path(grid, (1.5, 1.5, 0.0), (5.0, 5.0, 0.0), settings=settings(False))


@pytest.mark.slow
def test_too_large_turning_radius_ends_with_a_reason():
    cells = np.zeros((40, 200), dtype=np.uint8)  # a 2 m wide, 20 m long corridor
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 100
    s = PlannerSettings(
        vehicle=VehicleModel(robot_radius=0.2, turning_radius=3.0),
        hybrid=HybridAStarConfig(max_expansions=3000),
        ompl=OmplConfig(time_limit=0.3),
    )
    # facing the wrong way in a corridor narrower than a U-turn, forwards only
    with pytest.raises(NavigationError, match="no path|found no path|exhausted"):
        plan_path(make_grid(cells, 0.1), (5.0, 2.0, 0.0), (3.0, 2.0, 0.0), settings=s)
    with pytest.raises(NavigationError, match="found no path"):
        plan_path(make_grid(cells, 0.1), (5.0, 2.0, 0.0), (3.0, 2.0, 0.0), planner="ompl", settings=s)
    # with reversing allowed the same problem is easy
    s_rev = PlannerSettings(vehicle=VehicleModel(robot_radius=0.2, turning_radius=3.0, allow_reverse=True))
    result = plan_path(make_grid(cells, 0.1), (5.0, 2.0, 0.0), (3.0, 2.0, 0.0), settings=s_rev)
    assert result.length == pytest.approx(2.0, abs=0.1)


def test_empty_and_unknown_maps_are_refused():
    unknown = make_grid(np.full((50, 50), UNKNOWN, dtype=np.uint8), 0.1)
    with pytest.raises(NavigationError, match="no free space"):
        plan_path(unknown, (1.0, 1.0, 0.0), (4.0, 4.0, 0.0))
    with pytest.raises(NavigationError, match="no cells"):
        plan_path(make_grid(np.zeros((0, 0), np.uint8), 0.1), (1.0, 1.0, 0.0), (4.0, 4.0, 0.0))


@pytest.mark.parametrize("bad", [(math.nan, 1.0, 0.0), (1.0, math.inf, 0.0), (1.0, 2.0), "abc"])
def test_non_finite_or_malformed_goals_are_refused(costmap, bad):
    with pytest.raises(NavigationError, match="goal"):
        plan_path(costmap, (2.0, 2.0, 0.0), bad)


def test_unknown_planner_is_refused(costmap):
    with pytest.raises(NavigationError, match="unknown planner"):
        plan_path(costmap, (2.0, 2.0, 0.0), (4.0, 2.0, 0.0), planner="dijkstra")


def test_dubins_paths_reach_their_goal_and_match_ompl():
    from ompl import base as ob

    space = ob.DubinsStateSpace(0.7)
    a, b = space.allocState(), space.allocState()
    rng = np.random.default_rng(11)
    for _ in range(300):
        s = (*rng.uniform(-4, 4, 2), rng.uniform(-math.pi, math.pi))
        g = (*rng.uniform(-4, 4, 2), rng.uniform(-math.pi, math.pi))
        paths = dubins_paths(s, g, 0.7)
        assert paths, (s, g)
        xs, ys, ts = paths[0].sample(*s, 0.01)
        assert np.allclose([xs[-1], ys[-1]], g[:2], atol=1e-6)
        assert abs(math.remainder(ts[-1] - g[2], 2 * math.pi)) < 1e-6
        for st, p in ((a, s), (b, g)):
            st.setX(p[0])
            st.setY(p[1])
            st.setYaw(p[2])
        assert paths[0].length == pytest.approx(space.distance(a, b), abs=1e-9)


def test_inflation_is_a_disk_dilation():
    rng = np.random.default_rng(5)
    mask = rng.random((50, 60)) < 0.02
    for radius in (0.0, 1.0, 2.5, 5.3):
        expect = np.zeros_like(mask)
        rows, cols = np.nonzero(mask)
        for dr, dc in disk_offsets(radius):
            r, c = rows + dr, cols + dc
            ok = (r >= 0) & (r < 50) & (c >= 0) & (c < 60)
            expect[r[ok], c[ok]] = True
        assert np.array_equal(dilate(mask, radius), expect)


def test_distance_field_is_octile_in_the_open_and_goes_around_walls():
    from compute_peer.navigation.heuristic import DistanceField

    blocked = np.zeros((40, 40), dtype=bool)
    field = DistanceField(blocked, 0.1, (0.0, 0.0), 2, (0.1, 0.1))  # 0.2 m cells, goal in cell (0, 0)
    r, c = np.mgrid[0:20, 0:20]
    octile = (np.maximum(r, c) + (math.sqrt(2) - 1) * np.minimum(r, c)) * 0.2
    assert np.allclose(field.dist, octile)
    blocked[:, 20:22] = True  # a full-height wall: the right half is unreachable
    blocked[10:12, :20] = True  # and a wall with a gap on the right
    blocked[10:12, 18:20] = False
    field = DistanceField(blocked, 0.1, (0.0, 0.0), 2, (0.1, 0.1))
    assert np.isinf(field.lookup(np.array([3.0]), np.array([1.0])))[0]
    above = field.at(0.1, 3.0)
    assert above > 2 * 1.9  # around the gap at x = 1.8..2.0 and back
    assert math.isfinite(above)
