"""Scene objects (the IK target sphere, the goal pointer) where their latest pose puts them, and the static
scene (walls, shelves, tables) once, as boxes."""

from __future__ import annotations

from typing import Any, Iterable

import rerun as rr

from fabric.interfaces import OccupancyGrid, Pose
from user_peer.drawing.canvas import Canvas
from user_peer.geometry import quat_xyzw, world_to_map_pixels

__all__ = ["ObjectDrawer"]

OBJECT_COLOR = (40, 200, 80)


class ObjectDrawer:
    """Objects in 3D; a goal also on every map of ``grids`` (the map drawer's, shared)."""

    def __init__(self, canvas: Canvas, grids: dict[str, OccupancyGrid]) -> None:
        self.canvas = canvas
        self.grids = grids

    def log_object(self, oid: str, pose: Pose) -> bool:
        rec = self.canvas.rec
        path = f"world/objects/{oid}"
        rec.log(
            path, rr.Transform3D(translation=pose.position, quaternion=rr.Quaternion(xyzw=quat_xyzw(pose.quaternion)))
        )
        if self.canvas.once(path):
            if "goal" in oid:
                rec.log(
                    f"{path}/shape",
                    rr.Arrows3D(vectors=[[0.5, 0, 0]], colors=[OBJECT_COLOR], labels=[oid]),
                    static=True,
                )
            else:
                rec.log(
                    f"{path}/shape",
                    rr.Ellipsoids3D(
                        half_sizes=[[0.02, 0.02, 0.02]], colors=[OBJECT_COLOR], fill_mode="solid", labels=[oid]
                    ),
                    static=True,
                )
        for name, grid in self.grids.items():
            if "goal" in oid:
                rec.log(
                    f"map/{name}/objects/{oid}",
                    rr.Points2D(
                        world_to_map_pixels(grid, pose.position[:2]), radii=4.0, colors=[OBJECT_COLOR], labels=[oid]
                    ),
                )
        return True

    def log_scene(self, boxes: Iterable[Any], name: str = "scene") -> None:
        """The static scene once, as boxes: see :mod:`user_peer.scene_geometry`."""
        boxes = list(boxes)
        if not boxes:
            return
        self.canvas.rec.log(
            f"world/{name}",
            rr.Boxes3D(
                centers=[b.center for b in boxes],
                half_sizes=[b.half_size for b in boxes],
                quaternions=[rr.Quaternion(xyzw=b.quat_xyzw) for b in boxes],
                colors=[b.rgba for b in boxes],
                labels=[b.name for b in boxes],
                fill_mode="solid",
                show_labels=False,
            ),
            static=True,
        )
