"""Occupancy grids and planned paths: the map view's image, and each path in the world and on every map."""

from __future__ import annotations

from typing import Callable

import numpy as np
import rerun as rr

from fabric.interfaces import OccupancyGrid, Path
from user_peer.drawing.canvas import Canvas
from user_peer.geometry import grid_rgb, world_to_map_pixels

__all__ = ["MapDrawer"]


class MapDrawer:
    """Keeps the latest grid per map (bases and objects are drawn on every one) and each robot's latest path
    (drawn again on a map that comes later)."""

    def __init__(self, canvas: Canvas) -> None:
        self.canvas = canvas
        self.grids: dict[str, OccupancyGrid] = {}
        self.paths: dict[str, Path] = {}

    def log_map(self, name: str, grid: OccupancyGrid, color_of: Callable[[str], tuple[int, int, int]]) -> bool:
        """The grid as an image, and every path known so far on it (``color_of(robot)``: each path's colour)."""
        self.grids[name] = grid
        self.canvas.forget(f"map/{name}/robots/")  # its scale may differ
        rec = self.canvas.rec
        rec.log(f"map/{name}", rr.Image(grid_rgb(grid)))
        for rid, path in self.paths.items():
            if len(path):
                xy = np.stack([path.x, path.y], axis=1)
                rec.log(
                    f"map/{name}/paths/{rid}", rr.LineStrips2D([world_to_map_pixels(grid, xy)], colors=[color_of(rid)])
                )
        return True

    def log_path(self, rid: str, path: Path, color: tuple[int, int, int]) -> bool:
        """A robot's planned path on the ground and on every map; an empty path clears it."""
        rec = self.canvas.rec
        self.paths[rid] = path
        if len(path) == 0:
            rec.log(f"world/robots/{rid}/path", rr.Clear(recursive=False))
            return True
        pts = np.stack([path.x, path.y, np.full(len(path), 0.02)], axis=1)
        rec.log(f"world/robots/{rid}/path", rr.LineStrips3D([pts], radii=0.015, colors=[color]))
        for name, grid in self.grids.items():
            rec.log(f"map/{name}/paths/{rid}", rr.LineStrips2D([world_to_map_pixels(grid, pts[:, :2])], colors=[color]))
        return True
