"""Occupancy grids as :class:`fabric.interfaces.OccupancyGrid` values, and the cell arithmetic around them.

The fabric message is the map type everywhere (no second map class): cells are
row-major with row = y, 0 free .. 100 occupied, 255 unknown, and ``origin`` is
the world pose of the corner of cell (0, 0). Rotated origins are refused: no
map source in the fabric produces them and supporting them would cost every
cell lookup a rotation.
"""

from __future__ import annotations

import math

import numpy as np

from fabric.interfaces import Header, OccupancyGrid

from .errors import NavigationError

UNKNOWN = OccupancyGrid.UNKNOWN


def make_grid(
    cells: np.ndarray, resolution: float, origin_xy: tuple[float, float] = (0.0, 0.0), *, header: Header | None = None
) -> OccupancyGrid:
    return OccupancyGrid(
        float(resolution),
        np.array([origin_xy[0], origin_xy[1], 0.0]),
        np.asarray(cells, dtype=np.uint8),
        header or Header(),
    )


def check_grid(grid: OccupancyGrid) -> None:
    """Refuse grids the planners cannot use: rotated, or without cells."""
    if abs(float(grid.origin[2])) > 1e-9:
        raise NavigationError(f"maps with a rotated origin (yaw {float(grid.origin[2]):.3f} rad) are not supported")
    if grid.cells.size == 0:
        raise NavigationError("map has no cells")


def extent(grid: OccupancyGrid) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) of the mapped area in metres."""
    h, w = grid.cells.shape
    x0, y0 = float(grid.origin[0]), float(grid.origin[1])
    return x0, y0, x0 + w * grid.resolution, y0 + h * grid.resolution


def world_to_cell(grid: OccupancyGrid, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row, col, inside) for world points; row/col are clipped so they can index even when outside."""
    h, w = grid.cells.shape
    c = np.floor((np.asarray(x, dtype=np.float64) - grid.origin[0]) / grid.resolution)
    r = np.floor((np.asarray(y, dtype=np.float64) - grid.origin[1]) / grid.resolution)
    inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
    return np.clip(r, 0, h - 1).astype(np.intp), np.clip(c, 0, w - 1).astype(np.intp), inside


def contains(grid: OccupancyGrid, x: float, y: float) -> bool:
    return bool(world_to_cell(grid, np.array([x]), np.array([y]))[2][0])


def occupied_mask(grid: OccupancyGrid, threshold: int = 50, *, unknown_is_occupied: bool = True) -> np.ndarray:
    """Cells that block the robot: occupancy >= ``threshold`` (percent), and unknown ones if asked."""
    cells = grid.cells
    known = cells != UNKNOWN
    occ = known & (cells >= threshold)
    return occ | ~known if unknown_is_occupied else occ


def is_empty(grid: OccupancyGrid) -> bool:
    """True when no cell is known free: nothing to plan in."""
    return not bool((grid.cells < 50).any())


def disk_offsets(radius_cells: float) -> np.ndarray:
    """(dr, dc) of every cell whose centre lies within ``radius_cells`` of a centre cell (inclusive)."""
    n = int(math.floor(radius_cells + 1e-9))
    dr, dc = np.mgrid[-n : n + 1, -n : n + 1]
    keep = dr * dr + dc * dc <= radius_cells * radius_cells + 1e-9
    return np.stack([dr[keep], dc[keep]], axis=1)


def dilate(mask: np.ndarray, radius_cells: float) -> np.ndarray:
    """Binary dilation by a disk: a cell is set if any set cell's centre is within the radius of its centre.

    Done as an OR of shifted copies, one per row offset with a run of columns
    (a disk is a union of horizontal runs), which keeps it at O(radius) passes.
    """
    if radius_cells <= 0:
        return mask.copy()
    h, w = mask.shape
    n = int(math.floor(radius_cells + 1e-9))
    # horizontal dilation by every half-width 0..n once, reused per row offset
    padded = np.zeros((h, w + 2 * n), dtype=bool)
    padded[:, n : n + w] = mask
    runs = [mask.copy()]
    acc = mask.copy()
    for k in range(1, n + 1):
        acc = acc | padded[:, n - k : n - k + w] | padded[:, n + k : n + k + w]
        runs.append(acc.copy())
    out = np.zeros_like(mask)
    for dr in range(-n, n + 1):
        if abs(dr) >= h:  # a row offset past the map's edge reaches no row of it
            continue
        half = int(math.floor(math.sqrt(max(radius_cells * radius_cells - dr * dr, 0.0)) + 1e-9))
        src = runs[half]
        if dr >= 0:
            out[dr:, :] |= src[: h - dr, :]
        else:
            out[:dr, :] |= src[-dr:, :]
    return out
