"""Maps hold the world, not the robots in it: the cells under the robots, the mapper that leaves them out, and
where each robot stood when a scan was taken (issue 44)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from compute_peer.navigation import MapperConfig, OccupancyMapper
from compute_peer.navigation.grid import UNKNOWN, make_grid
from compute_peer.navigation.poses import PoseHistory
from compute_peer.navigation.robot_cells import Footprint, clear_robots, footprint_mask, robot_cells
from compute_peer.navigation.scan_mapping import ScanMapping
from compute_peer.navigation.scenes import Scene, room
from fabric.interfaces import Header, Pose, quaternion_from_yaw
from navscenes import pose_at, scan_at

RES = 0.05
ROBOT = 0.2  # half side of a square robot: its corners lie 0.283 m from its centre, inside a 0.30 m radius
RADIUS = 0.30


def _footprints():
    return st.lists(st.builds(Footprint, st.floats(-1.0, 3.0), st.floats(-1.0, 3.0), st.floats(0.0, 0.6)), max_size=4)


@settings(max_examples=60, deadline=None)
@given(
    cells=arrays(np.uint8, (30, 40), elements=st.sampled_from([0, 30, 100, UNKNOWN])),  # not a list: 10x faster drawn
    footprints=_footprints(),
    margin=st.floats(0.0, 0.2),
)
def test_clearing_frees_exactly_the_cells_under_the_robots(cells, footprints, margin):
    grid = make_grid(cells, RES, (0.2, -0.3))
    before = grid.cells.copy()
    out = clear_robots(grid, footprints, margin)
    # brute force: a cell is a robot's when its centre lies within radius + margin of the robot's centre
    cy, cx = np.mgrid[0:30, 0:40]
    wx, wy = 0.2 + (cx + 0.5) * RES, -0.3 + (cy + 0.5) * RES
    under = np.zeros((30, 40), dtype=bool)
    for f in footprints:
        under |= np.hypot(wx - f.x, wy - f.y) <= f.radius + margin + 1e-9
    assert np.array_equal(footprint_mask(grid, footprints, margin), under)
    assert (out.cells[under] == 0).all()
    assert np.array_equal(out.cells[~under], before[~under])
    assert np.array_equal(grid.cells, before)  # pure: the grid given is untouched
    assert robot_cells(out, footprints, margin) == 0
    assert robot_cells(grid, footprints, margin) == int(((before >= 50) & (before != UNKNOWN) & under).sum())
    if not (before[under] != 0).any():
        assert out is grid


def test_a_footprint_must_be_finite():
    with pytest.raises(ValueError):
        Footprint(math.nan, 0.0, 0.3)
    with pytest.raises(ValueError):
        Footprint(0.0, 0.0, -0.1)


def _scene_with_robot(x: float, y: float) -> Scene:
    return Scene(tuple(room(6.0, 0.2) + [(x - ROBOT, y - ROBOT, x + ROBOT, y + ROBOT)]), (0.0, 0.0, 6.0, 6.0))


def _mapper() -> OccupancyMapper:
    return OccupancyMapper(MapperConfig(resolution=RES, width=120, height=120, origin_x=0.0, origin_y=0.0))


def test_a_robot_seen_by_a_scan_is_no_wall_and_earlier_marks_are_cleared():
    scene = _scene_with_robot(3.5, 3.0)
    other = Footprint(3.5, 3.0, RADIUS)
    blind, seeing = _mapper(), _mapper()
    for yaw in (0.0, 0.4, -0.4):
        blind.integrate_scan(scan_at(scene, 1.5, 3.0, yaw), pose_at(1.5, 3.0, yaw))
        seeing.integrate_scan(scan_at(scene, 1.5, 3.0, yaw), pose_at(1.5, 3.0, yaw), robots=[other])
    assert robot_cells(blind.grid(threshold=0.65), [other]) > 5  # without the robots, the base is a wall
    built = seeing.grid(threshold=0.65)
    assert robot_cells(built, [other]) == 0
    assert (footprint_mask(built, [other]) <= (built.cells == 0)).all()  # the floor under it is known free
    assert (built.cells[:, 115:118] == 100).sum() > 20  # the hall's far wall is still there
    # the robot drives off: scans that know where it stands now clear what a scan blind to it marked
    blind.integrate_scan(scan_at(scene, 1.5, 3.0, 0.0), pose_at(1.5, 3.0, 0.0), robots=[other])
    assert robot_cells(blind.grid(threshold=0.65), [other]) == 0


def _pose(x, y, *, yaw=0.0, stamp=0.0, wall=0.0, source="sim-a"):
    return Pose(
        np.array([x, y, 0.0]),
        quaternion_from_yaw(yaw),
        header=Header(stamp=stamp, wall_ns=int(wall * 1e9), source=source),
    )


def test_where_a_robot_stood_when_a_scan_was_taken():
    poses = PoseHistory()
    for k in range(11):  # base2 of the same sim drives along x at 1 m/s, 10 Hz
        poses.add("base2", _pose(0.1 * k, 0.0, stamp=10.0 + 0.1 * k, wall=100.0 + 0.1 * k))
    same = poses.during("base2", Header(stamp=10.55, wall_ns=int(500e9), source="sim-a"))  # the wall clock aside
    assert len(same) == 1 and same[0].position[0] == pytest.approx(0.55)
    # a scan of another sim saw base2's mirror: every pose of the lag before the scan's wall time
    other = poses.during("base2", Header(stamp=3.0, wall_ns=int(100.55e9), source="sim-b"), lag=0.3)
    xs = sorted(float(p.position[0]) for p in other)
    assert xs[0] == pytest.approx(0.3) and xs[-1] == pytest.approx(0.55)
    # a robot whose last pose is long before the scan is gone: it stands nowhere
    assert poses.during("base2", Header(stamp=20.0, source="sim-a")) == []
    assert poses.during("base2", Header(wall_ns=int(110e9), source="sim-b")) == []
    assert poses.during("nobody", Header(stamp=10.0, source="sim-a")) == []


def _map_beside(parked: bool):
    """base1 turns a little at (1.5, 3) with base2 standing at (3.5, 3); the compute peer follows base2 when
    ``parked`` (it has its pose), else not (a robot it never heard of is a wall to it)."""
    scene = _scene_with_robot(3.5, 3.0)
    poses = PoseHistory()
    counters: dict[str, int] = {}
    scans = ScanMapping(
        poses,
        sensor_offset=lambda r: (0.0, 0.0, 0.0),
        radius=lambda r: RADIUS,
        counters=counters,
        config=MapperConfig(resolution=RES, width=120, height=120, origin_x=0.0, origin_y=0.0),
    )
    if parked:
        poses.add("base2", _pose(3.5, 3.0, stamp=1.0))
    for k, yaw in enumerate((0.0, 0.3, -0.3, 0.6)):
        stamp = 1.0 + 0.05 * k
        poses.add("base1", _pose(1.5, 3.0, yaw=yaw, stamp=stamp))
        assert scans.integrate("base1", scan_at(scene, 1.5, 3.0, yaw, stamp=stamp))
    assert counters["scans"] == 4
    return scans.grid(threshold=0.65)


def test_scan_mapping_leaves_out_every_robot_followed():
    base2 = [Footprint(3.5, 3.0, RADIUS)]
    assert robot_cells(_map_beside(parked=False), base2) > 5
    built = _map_beside(parked=True)
    assert robot_cells(built, base2) == 0
    assert (built.cells == 100).sum() > 100  # the hall is mapped


def test_a_robots_own_footprint_is_never_an_obstacle_to_its_own_start(connect):
    """A map that holds cells under the robot (a scan took it for a wall) still plans from where it stands; a start
    given at the same place is refused, naming the obstacle: only the robot's own pose vouches for its cells."""
    from compute_peer.navigation import PlannerSettings, VehicleModel, register_navigation
    from compute_peer.navigation.errors import NavigationError
    from fabric.interfaces import MapRequest, PlanRequest

    cells = np.zeros((80, 120), dtype=np.uint8)
    cells[:2, :] = cells[-2:, :] = cells[:, :2] = cells[:, -2:] = 100  # a 6 m x 4 m room
    cells[38:42, 22:24] = 100  # a ring's worth of hits at the robot's own position (1.15 m, 2 m)
    settings = PlannerSettings(vehicle=VehicleModel(robot_radius=0.25, turning_radius=0.5))
    with register_navigation(
        connect("compute", "compute-1"),
        robots=["base1"],
        settings=settings,
        sensor_offset=(0.0, 0.0, 0.0),
        discover=False,
    ) as nav:
        nav.map_service.handle(MapRequest("set", grid=make_grid(cells, RES)))
        nav.poses.add("base1", _pose(1.15, 2.0, stamp=1.0))
        goal = np.array([4.5, 2.0, 0.0])
        reply = nav.plan_service.handle(PlanRequest("base1", goal=goal), publish=False)
        assert (reply.path.x[0], reply.path.y[0]) == pytest.approx((1.15, 2.0))
        assert (reply.path.x[-1], reply.path.y[-1]) == pytest.approx((4.5, 2.0))
        with pytest.raises(NavigationError, match="start"):
            nav.plan_service.handle(PlanRequest("base1", goal=goal, start=np.array([1.15, 2.0, 0.0])), publish=False)


def test_a_robots_scans_wait_for_its_mounting_while_no_sim_answers(connect):
    """A loaded sim misses a lookup's answer: the robot's scans wait (its LIDAR's mounting is what keeps other
    robots inside their footprints), until the sims answer or none has for UNANSWERED_S."""
    from compute_peer.navigation.discovery import NO_OFFSET, UNANSWERED_S, RobotDescriptions
    from fabric.rate import FakeClock
    from robofabric.testing import wait_until

    clock = FakeClock(100.0)
    d = RobotDescriptions(connect("compute", "compute-1"), followed=lambda: (), clock=clock)
    try:
        assert d.sensor_offset("base1") is None  # a lookup starts; no sim serves srv/world here
        wait_until(lambda: d._lookup.ended > -math.inf, timeout=10.0, what="the lookup's end")
        clock.jump(1.5)
        assert d.sensor_offset("base1") is None  # unanswered: still waiting, asked again
        clock.jump(UNANSWERED_S)
        wait_until(lambda: d.sensor_offset("base1") == NO_OFFSET, timeout=10.0, what="the fallback")
    finally:
        d.close()


def test_a_plan_goes_around_the_robots_where_they_stand_now(connect):
    """The maps keep no robot, but a plan does not run through one: a student planning again after her base
    reported ``blocked`` gets a path around the base in her way."""
    from compute_peer.navigation import PlannerSettings, VehicleModel, register_navigation
    from fabric.interfaces import MapRequest, PlanRequest

    cells = np.zeros((80, 120), dtype=np.uint8)
    cells[:2, :] = cells[-2:, :] = cells[:, :2] = cells[:, -2:] = 100  # a 6 m x 4 m room, nothing inside
    settings = PlannerSettings(vehicle=VehicleModel(robot_radius=0.3, turning_radius=0.5))
    with register_navigation(
        connect("compute", "compute-1"), settings=settings, sensor_offset=(0.0, 0.0, 0.0), discover=False
    ) as nav:
        nav.map_service.handle(MapRequest("set", grid=make_grid(cells, RES)))
        nav.poses.add("base1", _pose(1.0, 2.0, stamp=5.0))
        goal = np.array([5.0, 2.0, 0.0])
        alone = nav.plan_service.handle(PlanRequest("base1", goal=goal), publish=False)
        assert alone.length == pytest.approx(4.0, abs=0.05)  # straight across
        nav.poses.add("base2", _pose(3.0, 2.0, stamp=5.0))  # parked on that line
        around = nav.plan_service.handle(PlanRequest("base1", goal=goal), publish=False)
        assert np.hypot(around.path.x - 3.0, around.path.y - 2.0).min() >= 2 * 0.3  # never through base2
        assert (around.path.x[-1], around.path.y[-1]) == pytest.approx((5.0, 2.0))
        nav.poses.add("base1", _pose(1.0, 2.0, stamp=8.0))  # base2's pose is now 3 s older than base1's: gone
        assert nav.plan_service.handle(PlanRequest("base1", goal=goal), publish=False).length == pytest.approx(
            4.0, abs=0.05
        )
