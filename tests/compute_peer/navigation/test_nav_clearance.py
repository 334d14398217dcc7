"""Hybrid A* keeps clear of corners where it costs little (issue 44): the warehouse's shelves' gap, planned with and
without the charge for running within ``costmap.NEAR`` of the inflated obstacles."""

from __future__ import annotations

import math

import numpy as np

from compute_peer.navigation import PlannerSettings, plan_path
from compute_peer.navigation.costmap import NEAR, build_costmap
from compute_peer.navigation.grid import make_grid
from compute_peer.navigation.hybrid_astar import HybridAStarConfig
from compute_peer.navigation.model import VehicleModel

RES = 0.05
SHELVES = ((-2.5, 2.5, 1.5, 0.3), (2.5, 2.5, 1.5, 0.3))  # centre, half sizes: a 2 m gap between x = -1 and 1


def _warehouse():
    cells = np.zeros((200, 200), np.uint8)
    for cx, cy, hx, hy in SHELVES:
        cells[
            int((cy - hy + 5) / RES) : int(math.ceil((cy + hy + 5) / RES)),
            int((cx - hx + 5) / RES) : int(math.ceil((cx + hx + 5) / RES)),
        ] = 100
    return make_grid(cells, RES, (-5.0, -5.0))


def _clearance(path) -> float:
    return min(
        math.hypot(max(abs(x - cx) - hx, 0.0), max(abs(y - cy) - hy, 0.0))
        for x, y in zip(path.x, path.y)
        for cx, cy, hx, hy in SHELVES
    )


def test_a_path_through_the_gap_keeps_clear_of_the_shelves_corners_when_it_costs_little():
    grid = _warehouse()
    vehicle = VehicleModel(robot_radius=0.3)
    start, goal = (3.0, 0.0, math.pi / 2), (-1.75, 4.3, math.pi)  # diagonal past the corner at (1, 2.2)
    bare = plan_path(
        grid, start, goal, settings=PlannerSettings(vehicle=vehicle, hybrid=HybridAStarConfig(near_penalty=0.0))
    )
    kept = plan_path(grid, start, goal, settings=PlannerSettings(vehicle=vehicle))
    cm = build_costmap(grid, 0.3)
    assert cm.near is not None and cm.near.any() and not (cm.near & cm.blocked).any()
    assert _clearance(bare) < 0.3 + cm.margin + 0.05  # the shortest way hugs the corner
    assert _clearance(kept) > _clearance(bare) + 0.05  # charged for it, the path keeps off
    assert kept.length < 1.1 * bare.length  # for little more length
    assert NEAR > 0.05
