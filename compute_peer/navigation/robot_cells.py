"""Maps hold the world, not the robots in it: the cells under the robots (pure: grid + footprints in, grid out).

Robots see each other: a base's LIDAR hits another base as it would a wall, and a map that kept those hits
would hold the robots where they once stood, as walls, in front of the next plan (a student's start "within the
robot radius of an obstacle" because another base had scanned her). So every scan is folded in knowing where
every robot of the world stood when it was taken (a :class:`Footprint` each, the robot's pose interpolated to
the scan's stamp): no end point inside a footprint marks a cell occupied, and the footprint's cells are cleared
(seen free: the floor under a robot is floor), which also undoes what an earlier scan marked there.

A footprint covers the robot's radius (the circle about its turn point that contains it) plus
:data:`ROBOT_MARGIN`: a ray ends on the robot's surface, in a cell whose centre may lie up to half a diagonal
beyond it, and a robot of another sim is seen as that sim's mirror of it, a stream period or so behind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Iterable

import numpy as np

from fabric.interfaces import OccupancyGrid

__all__ = [
    "ROBOT_MARGIN",
    "Footprint",
    "clear_robots",
    "footprint_indices",
    "footprint_mask",
    "mark_robots",
    "robot_cells",
]

ROBOT_MARGIN = 0.1
"""Metres around a robot's radius whose cells count as the robot's: a hit on its surface lands in a cell up to
0.7 cell beyond it (3.5 cm at 5 cm cells), and its pose may be a few centimetres off where the scan saw it."""


@dataclass(frozen=True, slots=True)
class Footprint:
    """A robot on the floor: the disk of ``radius`` about (``x``, ``y``) in world metres."""

    x: float
    y: float
    radius: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.x) and math.isfinite(self.y) and math.isfinite(self.radius) and self.radius >= 0):
            raise ValueError(f"a footprint needs a finite position and a radius >= 0, got {self}")


def footprint_indices(
    shape: tuple[int, int],
    resolution: float,
    origin_xy: tuple[float, float],
    footprints: Iterable[Footprint],
    margin: float = ROBOT_MARGIN,
) -> np.ndarray:
    """Flat (row-major) indices of the cells whose centre lies within a footprint's radius + ``margin``.

    Each footprint costs only its bounding box; cells off the grid are left out; an index appears once.
    """
    h, w = shape
    parts = []
    for f in footprints:
        rc = (f.radius + margin) / resolution
        if rc <= 0:
            continue
        cx, cy = (f.x - origin_xy[0]) / resolution, (f.y - origin_xy[1]) / resolution
        r0, r1 = max(math.floor(cy - rc), 0), min(math.ceil(cy + rc) + 1, h)
        c0, c1 = max(math.floor(cx - rc), 0), min(math.ceil(cx + rc) + 1, w)
        if r0 >= r1 or c0 >= c1:
            continue
        dy2 = (np.arange(r0, r1) + 0.5 - cy) ** 2
        dx2 = (np.arange(c0, c1) + 0.5 - cx) ** 2
        rows, cols = np.nonzero(dy2[:, None] + dx2[None, :] <= rc * rc + 1e-9)
        parts.append((rows + r0) * w + (cols + c0))
    if not parts:
        return np.zeros(0, dtype=np.intp)
    return np.unique(np.concatenate(parts)) if len(parts) > 1 else parts[0]


def footprint_mask(grid: OccupancyGrid, footprints: Iterable[Footprint], margin: float = ROBOT_MARGIN) -> np.ndarray:
    """The cells of ``grid`` under the robots (radius + ``margin``), as a boolean array of the grid's shape."""
    mask = np.zeros(grid.cells.shape, dtype=bool)
    idx = footprint_indices(
        grid.cells.shape, grid.resolution, (float(grid.origin[0]), float(grid.origin[1])), footprints, margin
    )
    mask.reshape(-1)[idx] = True
    return mask


def clear_robots(grid: OccupancyGrid, footprints: Iterable[Footprint], margin: float = ROBOT_MARGIN) -> OccupancyGrid:
    """``grid`` with the cells under the robots free (0); the same object when none was anything else."""
    mask = footprint_mask(grid, footprints, margin)
    if not (grid.cells[mask] != 0).any():
        return grid
    cells = grid.cells.copy()
    cells[mask] = 0
    return replace(grid, cells=cells)


def mark_robots(grid: OccupancyGrid, footprints: Iterable[Footprint], margin: float = 0.0) -> OccupancyGrid:
    """``grid`` with the cells under the robots occupied (100): where they stand now, for one plan (the map itself
    keeps no robot); the same object when there is none."""
    mask = footprint_mask(grid, footprints, margin)
    if not mask.any():
        return grid
    cells = grid.cells.copy()
    cells[mask] = 100
    return replace(grid, cells=cells)


def robot_cells(
    grid: OccupancyGrid, footprints: Iterable[Footprint], margin: float = ROBOT_MARGIN, *, threshold: int = 50
) -> int:
    """How many cells under the robots ``grid`` holds as occupied (>= ``threshold`` percent, unknown aside)."""
    cells = grid.cells[footprint_mask(grid, footprints, margin)]
    return int(((cells >= threshold) & (cells != OccupancyGrid.UNKNOWN)).sum())
