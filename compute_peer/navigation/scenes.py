"""Synthetic scenes with known geometry: the ground truth for mapping tests and planning benchmarks.

A scene is a set of axis-aligned boxes (walls, pillars) in a square room.
:func:`raycast` computes exact LIDAR ranges against them (slab method, all
rays at once) and :func:`rasterize` draws the true occupancy grid, so a test
can compare what the mapper built with what is really there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fabric.interfaces import OccupancyGrid

from .grid import make_grid

Box = tuple[float, float, float, float]  # x_min, y_min, x_max, y_max


@dataclass(frozen=True, slots=True)
class Scene:
    boxes: tuple[Box, ...]
    bounds: Box  # the area a map of it should cover

    def rasterize(self, resolution: float) -> OccupancyGrid:
        """True map: a cell is occupied (100) when its centre lies in a box, free (0) otherwise."""
        x0, y0, x1, y1 = self.bounds
        w = int(round((x1 - x0) / resolution))
        h = int(round((y1 - y0) / resolution))
        cx = x0 + (np.arange(w) + 0.5) * resolution
        cy = y0 + (np.arange(h) + 0.5) * resolution
        occ = np.zeros((h, w), dtype=bool)
        for bx0, by0, bx1, by1 in self.boxes:
            occ |= ((cy >= by0) & (cy <= by1))[:, None] & ((cx >= bx0) & (cx <= bx1))[None, :]
        return make_grid(np.where(occ, 100, 0).astype(np.uint8), resolution, (x0, y0))

    def raycast(self, x: float, y: float, angles: np.ndarray, range_max: float) -> np.ndarray:
        """Range along each world-frame angle from (x, y) to the nearest box face; ``range_max`` on a miss."""
        a = np.asarray(angles, dtype=np.float64)
        dx, dy = np.cos(a), np.sin(a)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_x = np.where(np.abs(dx) > 1e-12, 1.0 / dx, np.inf)
            inv_y = np.where(np.abs(dy) > 1e-12, 1.0 / dy, np.inf)
        b = np.array(self.boxes, dtype=np.float64)  # (B, 4)
        with np.errstate(invalid="ignore"):
            tx1 = (b[None, :, 0] - x) * inv_x[:, None]
            tx2 = (b[None, :, 2] - x) * inv_x[:, None]
            ty1 = (b[None, :, 1] - y) * inv_y[:, None]
            ty2 = (b[None, :, 3] - y) * inv_y[:, None]
        # rays parallel to a slab: inside it -> whole line, outside -> never
        in_x = (b[None, :, 0] <= x) & (x <= b[None, :, 2])
        in_y = (b[None, :, 1] <= y) & (y <= b[None, :, 3])
        par_x = ~np.isfinite(inv_x)[:, None]
        par_y = ~np.isfinite(inv_y)[:, None]
        tmin_x = np.where(par_x, np.where(in_x, -np.inf, np.inf), np.minimum(tx1, tx2))
        tmax_x = np.where(par_x, np.where(in_x, np.inf, -np.inf), np.maximum(tx1, tx2))
        tmin_y = np.where(par_y, np.where(in_y, -np.inf, np.inf), np.minimum(ty1, ty2))
        tmax_y = np.where(par_y, np.where(in_y, np.inf, -np.inf), np.maximum(ty1, ty2))
        tmin = np.maximum(tmin_x, tmin_y)
        tmax = np.minimum(tmax_x, tmax_y)
        hit = (tmax >= tmin) & (tmax > 0)
        t = np.where(hit, np.maximum(tmin, 0.0), np.inf).min(axis=1)
        return np.minimum(t, range_max)


def room(size: float = 20.0, wall: float = 0.2) -> list[Box]:
    """The four walls of a square room from (0, 0) to (size, size)."""
    return [
        (0.0, 0.0, size, wall),
        (0.0, size - wall, size, size),
        (0.0, 0.0, wall, size),
        (size - wall, 0.0, size, size),
    ]


def office(size: float = 20.0) -> Scene:
    """A 20 m room with two long partition walls (gaps at alternate ends) and a few pillars: a planning benchmark."""
    s = size / 20.0
    boxes = room(size)
    boxes += [
        (6.0 * s, 0.0, 6.3 * s, 14.0 * s),  # partition open at the top
        (13.0 * s, 6.0 * s, 13.3 * s, size),  # partition open at the bottom
        (2.5 * s, 8.0 * s, 3.5 * s, 9.0 * s),
        (9.0 * s, 4.0 * s, 10.0 * s, 5.0 * s),
        (9.0 * s, 12.0 * s, 10.0 * s, 13.0 * s),
        (16.0 * s, 10.0 * s, 17.0 * s, 11.0 * s),
    ]
    return Scene(tuple(boxes), (0.0, 0.0, size, size))


def scan_angles(rays: int = 240, fov_deg: float = 135.0) -> tuple[float, float]:
    """(angle_min, angle_increment) of a centred LIDAR fan."""
    fov = math.radians(fov_deg)
    return -fov / 2.0, fov / (rays - 1)
