"""Log-odds mapping recovers a known scene's walls from ray-cast scans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from compute_peer.navigation import MapperConfig, NavigationError, OccupancyMapper
from compute_peer.navigation.grid import UNKNOWN, dilate
from navscenes import drive_poses, pose_at, scan_at, small_room

RES = 0.05


def mapped_room():
    scene = small_room()
    mapper = OccupancyMapper(MapperConfig(resolution=RES, width=200, height=200, origin_x=0.0, origin_y=0.0))
    for x, y, yaw in drive_poses(scene):
        mapper.integrate_scan(scan_at(scene, x, y, yaw), pose_at(x, y, yaw))
    return scene, mapper


def test_mapping_recovers_the_walls_of_a_known_scene():
    scene, mapper = mapped_room()
    built = mapper.grid(threshold=0.65)
    truth = scene.rasterize(RES).cells == 100
    occupied = built.cells == 100
    free = built.cells == 0
    # wall surfaces: true occupied cells that touch free space
    surface = truth & dilate(~truth, 1)
    assert (occupied & surface).sum() / surface.sum() >= 0.97
    # nothing occupied away from the true walls (one cell of slack for hits on cell borders)
    assert not (occupied & ~dilate(truth, 1)).any()
    # open floor (more than a cell from any wall) is known and free
    floor = ~dilate(truth, 1.5)
    assert free[floor].mean() >= 0.99
    # the inside of thick walls was never seen
    deep = truth & ~dilate(~truth, 2)
    assert (built.cells[deep] == UNKNOWN).all()


def test_probability_map_and_threshold():
    scene, mapper = mapped_room()
    prob = mapper.grid()
    binary = mapper.grid(threshold=0.65)
    known = prob.cells != UNKNOWN
    assert np.array_equal(known, binary.cells != UNKNOWN)
    assert set(np.unique(binary.cells)) <= {0, 100, UNKNOWN}
    assert np.array_equal(binary.cells[known] == 100, mapper.probabilities()[known] > 0.65)
    with pytest.raises(NavigationError, match="threshold"):
        mapper.grid(threshold=1.5)


def test_misses_mark_free_space_only_and_rays_may_leave_the_map():
    mapper = OccupancyMapper(MapperConfig(resolution=0.1, width=50, height=50, origin_x=0.0, origin_y=0.0))
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    # at the corner of the map, every ray reading range_max: nothing hit, half the rays leave the grid
    mapper.integrate(np.full(360, 20.0), angles, 20.0, 0.05, 0.05, 0.3)
    grid = mapper.grid(threshold=0.5)
    assert not (grid.cells == 100).any()
    assert (grid.cells == 0).sum() > 2000
    # a sensor outside the map is fine too: only the cells inside get updates
    mapper.integrate(np.full(4, 3.0), np.zeros(4), 20.0, -1.0, 2.0, 0.0)
    assert mapper.scans == 2


def test_hits_win_over_free_marks_and_clamp():
    c = MapperConfig(resolution=0.1, width=40, height=40, origin_x=0.0, origin_y=0.0)
    mapper = OccupancyMapper(c)
    for _ in range(50):
        mapper.integrate(np.array([1.0]), np.array([0.0]), 5.0, 0.55, 0.55, 0.0)
    assert mapper.logodds.max() == pytest.approx(c.l_max)
    assert mapper.logodds.min() == pytest.approx(c.l_min)
    row, col = 5, 15  # the end point (1.55, 0.55)
    assert mapper.logodds[row, col] == pytest.approx(c.l_max)
    assert mapper.logodds[row, 5:15] == pytest.approx(c.l_min)


def test_bad_scans_are_refused():
    mapper = OccupancyMapper(MapperConfig(resolution=0.1, width=10, height=10))
    with pytest.raises(NavigationError):
        mapper.integrate(np.ones(3), np.zeros(4), 5.0, 0.0, 0.0, 0.0)
    with pytest.raises(NavigationError):
        mapper.integrate(np.ones(3), np.zeros(3), 5.0, math.nan, 0.0, 0.0)
    with pytest.raises(NavigationError):
        MapperConfig(resolution=-1.0)
    assert mapper.scans == 0


def test_the_floor_under_the_robot_is_marked_free():
    mapper = OccupancyMapper(MapperConfig(resolution=0.1, width=40, height=40, origin_x=0.0, origin_y=0.0))
    mapper.clear_footprint(2.0, 2.0, 0.3)
    cells = mapper.grid(threshold=0.5).cells
    centres = (np.arange(40) + 0.5) * 0.1
    disk = (centres[:, None] - 2.0) ** 2 + (centres[None, :] - 2.0) ** 2 <= 0.3**2 + 1e-9
    assert np.array_equal(cells == 0, disk) and np.array_equal(cells == UNKNOWN, ~disk)
    mapper.clear_footprint(-5.0, -5.0, 0.3)  # off the map: nothing, no error
    assert np.array_equal(mapper.grid(threshold=0.5).cells == 0, disk)
